//! The WGSL torus primitive (shaders/csg/torus.wgsl) agrees ray by ray with its CPU twin,
//! `hytrace_csg::kernel::primitive_spans::<f32>` / `primitive_sdf::<f32>` for
//! `TypeCode::Torus`, on lavapipe in CI (HYTRACE_REQUIRE_GPU=1 fails without an adapter).
//!
//! Agreement of one ray: the same number of spans; every span end within
//! `1e-5 * size + 4 eps |t d|` of the CPU's along the ray (size = rtor + rmax; GPU values of
//! magnitude >= 1e38 count as infinite); unit normals within 1e-4 (both zero at infinite
//! ends); the sdf at the origin within `1e-5 * size + 4 eps |sdf|`. On lavapipe every ray
//! is in fact bit-identical (the count is printed); the tolerance leaves room for a compiler
//! that contracts a*b+c into an fma, whose last-bit differences near a tangency can move a
//! crossing or flip a chord of rounding-noise depth.

use bytemuck::cast_slice;
mod common;
use common::{PcgDraws as Rng, Random};

use hytrace_csg::kernel::{primitive_sdf, primitive_spans};
use hytrace_csg::V3;
use hytrace_foundry::TypeCode;
use hytrace_testkit::torus::{tube_point, TorusRays};
use hytrace_testkit::vec3::{add, dot, normalized as unit, scale as mul, sub};
use hytrace_trace::gpu::oneshot::{run, Buffer};
use hytrace_trace::gpu::GpuContext;

/// Floats per input item and per output item (see shaders/kernels/torus_probe.wgsl).
const IN_STRIDE: usize = 16;
const OUT_STRIDE: usize = 36;
/// GPU magnitudes from which a value means infinity.
const GPU_INF: f32 = 1.0e38;
/// Tolerances (see the module documentation).
const T_TOL: f64 = 1e-5;
const NORMAL_TOL: f64 = 1e-4;
const REQUIRED_RATE: f64 = 0.999;
const PER_FAMILY: usize = 400;

/// The torus draws of this test, on the shared generator.
trait TorusDraws: Random {
    /// `(rmin, rmax, rtor)` of one of several shapes, sizes 1e-2 to 1e2.
    fn torus(&mut self, shape: usize) -> (f64, f64, f64) {
        let rtor = 10f64.powf(self.range(-2.0, 2.0));
        let rmax = match shape % 6 {
            // Thin tube.
            0 => rtor * 10f64.powf(self.range(-2.0, -1.0)),
            // Fat tube.
            1 => rtor * self.range(0.5, 0.95),
            // Horn torus.
            2 => rtor,
            // Spindle torus (the outer surface of the points within rmax of the core).
            3 => rtor * self.range(1.0, 1.8),
            _ => rtor * self.range(0.1, 0.95),
        };
        let rmin = if shape % 2 == 1 || shape % 6 == 4 {
            rmax * self.range(0.2, 0.9)
        } else {
            0.0
        };
        (rmin, rmax, rtor)
    }
}

impl TorusDraws for Rng {}

type P = [f64; 3];

/// One probe: a torus `[rmin, rmax, rtor]` and a ray, in f32.
#[derive(Clone, Copy, Debug)]
struct Item {
    family: &'static str,
    p: [f32; 6],
    o: [f32; 3],
    d: [f32; 3],
}

impl Item {
    fn new(family: &'static str, (rmin, rmax, rtor): (f64, f64, f64), o: P, d: P) -> Self {
        Item {
            family,
            p: [rmin as f32, rmax as f32, rtor as f32, 0.0, 0.0, 0.0],
            o: o.map(|x| x as f32),
            d: d.map(|x| x as f32),
        }
    }
    /// rtor + rmax (in magnitude: degenerate parameters may be negative).
    fn size(&self) -> f64 {
        (self.p[1].abs() + self.p[2].abs()) as f64
    }
    /// The same ray with its origin moved to the closest approach to the torus centre,
    /// exactly as `Leaf::step` does before calling `primitive_spans`.
    fn recentred(&self) -> Self {
        let o = V3::new(self.o[0], self.o[1], self.o[2]);
        let d = V3::new(self.d[0], self.d[1], self.d[2]);
        let shift = -o.dot(d) / d.length_squared();
        let shift = if shift.is_finite() { shift } else { 0.0 };
        let c = o.at(d, shift);
        Item {
            o: [c.x, c.y, c.z],
            ..*self
        }
    }
}

fn families() -> Vec<Item> {
    let mut rng = Rng::new(0x70_7275);
    let mut items = Vec::new();
    let two_pi = 2.0 * std::f64::consts::PI;
    for i in 0..PER_FAMILY {
        // Random rays near the torus.
        let t = rng.torus(i);
        let o = rng.torus_near(t.1, t.2, 3.0);
        let d = if rng.uniform() < 0.7 {
            unit(sub(rng.torus_near(t.1, t.2, 1.0), o))
        } else {
            rng.direction()
        };
        items.push(Item::new("near", t, o, d));

        // Origin inside the (outer) tube.
        let t = rng.torus(i);
        let (phi, theta) = (rng.range(0.0, two_pi), rng.range(0.0, two_pi));
        let (o, _) = tube_point(t.2, phi, theta, 0.999 * t.1 * rng.uniform().sqrt());
        items.push(Item::new("inside_tube", t, o, rng.direction()));

        // Through the hole (nearly in the equatorial plane for half of them).
        let t = rng.torus(i);
        let phi = rng.range(0.0, two_pi);
        let rho = 0.95 * (t.2 - t.1).max(0.0) * rng.uniform().sqrt();
        let h = [rho * phi.cos(), rho * phi.sin(), rng.range(-t.1, t.1)];
        let mut d = rng.direction();
        if i % 2 == 0 {
            d[2] *= 0.05;
            d = unit(d);
        }
        let o = sub(h, mul(d, rng.range(0.5, 3.0) * (t.1 + t.2)));
        items.push(Item::new("through_hole", t, o, d));

        // Axis-aligned directions and zero components.
        let t = rng.torus(i);
        let (o, d) = rng.torus_axis_ray(t.1, t.2, i);
        items.push(Item::new("axis_aligned", t, o, d));

        // Origins 1e5 mm away.
        let t = rng.torus(i);
        let target = rng.torus_near(t.1, t.2, 1.0);
        let d = rng.direction();
        items.push(Item::new("far_1e5", t, sub(target, mul(d, 1e5)), d));

        // Non-unit directions.
        let t = rng.torus(i);
        let o = rng.torus_near(t.1, t.2, 3.0);
        let d = unit(sub(rng.torus_near(t.1, t.2, 1.0), o));
        let k = [1e-2, 1e2, 3.7][i % 3];
        items.push(Item::new("non_unit", t, o, mul(d, k)));

        // Tangent to the outer tube, shifted by -1e-3 rmax (a short chord), +1e-3 rmax (a
        // near miss) or 0.
        let t = rng.torus(i);
        let (phi, theta) = (rng.range(0.0, two_pi), rng.range(0.0, two_pi));
        let (p, n) = tube_point(t.2, phi, theta, t.1);
        let dir = rng.direction();
        let d = unit(sub(dir, mul(n, dot(dir, n))));
        let offset = [-1e-3, 1e-3, 0.0][i % 3] * t.1;
        let back = rng.range(1.0, 3.0) * (t.1 + t.2);
        let o = sub(add(p, mul(n, offset)), mul(d, back));
        items.push(Item::new("grazing", t, o, d));

        // Horn torus, rays aimed within 1e-3 of the size at the pinch point.
        let (_, _, rtor) = rng.torus(i);
        let t = (0.0, rtor, rtor);
        let o = rng.torus_near(rtor, rtor, 3.0);
        let d = unit(sub(rng.torus_near(rtor, rtor, 1e-3), o));
        items.push(Item::new("horn_pinch", t, o, d));

        // Spindle torus, rays near the dimples on the axis.
        let (_, _, rtor) = rng.torus(i);
        let r = rtor * rng.range(1.0, 2.0);
        let o = rng.torus_near(r, rtor, 3.0);
        let (z, e) = ((r * r - rtor * rtor).sqrt(), 1e-3 * r);
        let target = [rng.range(-e, e), rng.range(-e, e), z + rng.range(-e, e)];
        items.push(Item::new(
            "spindle_dimple",
            (0.0, r, rtor),
            o,
            unit(sub(target, o)),
        ));
    }
    items
}

/// Hand-made cases from the CPU tests of kernel/torus.rs.
fn named() -> Vec<Item> {
    let t = (0.0, 1.0, 3.0);
    let hollow = (0.5, 1.0, 3.0);
    let mut v = vec![
        Item::new("diameter", t, [-10.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        Item::new(
            "diameter_hollow",
            hollow,
            [-10.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ),
        Item::new("parallel_axis_len2", t, [3.0, 0.0, -10.0], [0.0, 0.0, 2.0]),
        Item::new("along_axis", t, [0.0, 0.0, -10.0], [0.0, 0.0, 1.0]),
        Item::new("inside_backwards", t, [3.5, 0.0, 0.0], [-1.0, 0.0, 0.0]),
        Item::new(
            "inner_equator_tangent",
            t,
            [2.0, 0.0, -10.0],
            [0.0, 0.0, 1.0],
        ),
        Item::new(
            "outer_equator_tangent",
            t,
            [4.0, 0.0, -10.0],
            [0.0, 0.0, 1.0],
        ),
        Item::new("top_tangent", t, [-10.0, 0.0, 1.0], [1.0, 0.0, 0.0]),
        Item::new("misses_sphere", t, [-10.0, 0.0, 4.5], [1.0, 0.0, 0.0]),
        Item::new("zero_direction", t, [-10.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        Item::new(
            "zero_rmax",
            (0.0, 0.0, 3.0),
            [-10.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ),
        Item::new(
            "negative_rtor",
            (0.0, 1.0, -3.0),
            [-10.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ),
        Item::new(
            "horn_axis",
            (0.0, 2.0, 2.0),
            [0.0, 0.0, -10.0],
            [0.0, 0.0, 1.0],
        ),
        Item::new(
            "horn_equator",
            (0.0, 2.0, 2.0),
            [-10.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ),
        Item::new(
            "spindle_axis",
            (0.0, 3.0, 2.0),
            [0.0, 0.0, -10.0],
            [0.0, 0.0, 1.0],
        ),
        Item::new("far_1e5_x", t, [-1e5, 0.0, 0.5], [1.0, 0.0, 0.0]),
        Item::new("far_1e5_diag", t, [-1e5, -1e5, 0.1], [1.0, 1.0, 0.0]),
    ];
    for k in [1e-20, 1e-6, 1e6, 1e20] {
        v.push(Item::new("scaled_dir", t, [-10.0, 0.0, 0.5], [k, 0.0, 0.0]));
    }
    v
}

/// One GPU result: span count, sdf and the spans (t0, t1, n0, n1).
struct Got {
    spans: Vec<(f32, f32, [f32; 3], [f32; 3])>,
    sdf: f32,
}

fn gpu_run(ctx: &GpuContext, items: &[Item]) -> Vec<Got> {
    let mut input = vec![0f32; items.len() * IN_STRIDE];
    for (k, it) in items.iter().enumerate() {
        let b = k * IN_STRIDE;
        input[b..b + 6].copy_from_slice(&it.p);
        input[b + 8..b + 11].copy_from_slice(&it.o);
        input[b + 12..b + 15].copy_from_slice(&it.d);
    }
    let out_bytes = (items.len() * OUT_STRIDE * 4) as u64;
    let outs = run(
        ctx,
        "kernels/torus_probe",
        "torus_probe",
        items.len() as u32,
        &[vec![
            Buffer::Input(cast_slice(&input)),
            Buffer::Output(out_bytes),
        ]],
    )
    .expect("torus probe dispatch");
    let out: &[f32] = cast_slice(&outs[0]);
    (0..items.len())
        .map(|k| {
            let w = &out[k * OUT_STRIDE..(k + 1) * OUT_STRIDE];
            let n = w[0] as usize;
            let spans = (0..n.min(4))
                .map(|s| {
                    let v = &w[4 + 8 * s..12 + 8 * s];
                    (v[0], v[1], [v[2], v[3], v[4]], [v[5], v[6], v[7]])
                })
                .collect();
            Got { spans, sdf: w[1] }
        })
        .collect()
}

fn cpu_run(it: &Item) -> Got {
    let o = V3::new(it.o[0], it.o[1], it.o[2]);
    let d = V3::new(it.d[0], it.d[1], it.d[2]);
    let spans = primitive_spans::<f32>(TypeCode::Torus, &it.p, &[], o, d, 0.0);
    let n3 = |v: V3<f32>| [v.x, v.y, v.z];
    Got {
        spans: spans
            .as_slice()
            .iter()
            .map(|s| (s.t0, s.t1, n3(s.n0), n3(s.n1)))
            .collect(),
        sdf: primitive_sdf::<f32>(TypeCode::Torus, &it.p, &[], o),
    }
}

/// Why a GPU result disagrees with the CPU's, or None.
fn disagreement(it: &Item, gpu: &Got, cpu: &Got) -> Option<String> {
    let size = it.size();
    let dlen = it.d.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
    let same_t = |g: f32, c: f32| {
        if c.is_infinite() || g.abs() >= GPU_INF {
            return c.is_infinite() && g.abs() >= GPU_INF && (c > 0.0) == (g > 0.0);
        }
        let (g, c) = (g as f64, c as f64);
        (g - c).abs() * dlen <= T_TOL * size + 4.0 * f32::EPSILON as f64 * c.abs() * dlen
    };
    let same_n = |g: [f32; 3], c: [f32; 3]| {
        let unit = |v: [f32; 3]| {
            let v = v.map(f64::from);
            let l = dot(v, v).sqrt();
            if l > 0.0 {
                mul(v, 1.0 / l)
            } else {
                v
            }
        };
        let e = sub(unit(g), unit(c));
        dot(e, e).sqrt() <= NORMAL_TOL
    };
    if gpu.spans.len() != cpu.spans.len() {
        return Some(format!("{} spans vs {}", gpu.spans.len(), cpu.spans.len()));
    }
    for (k, (g, c)) in gpu.spans.iter().zip(&cpu.spans).enumerate() {
        if !same_t(g.0, c.0) || !same_t(g.1, c.1) {
            return Some(format!("span {k} ends"));
        }
        if !same_n(g.2, c.2) || !same_n(g.3, c.3) {
            return Some(format!("span {k} normals"));
        }
    }
    let (g, c) = (gpu.sdf as f64, cpu.sdf as f64);
    if (g - c).abs() > T_TOL * size + 4.0 * f32::EPSILON as f64 * c.abs() {
        return Some("sdf".to_string());
    }
    None
}

/// Whether the GPU's spans and sdf are the CPU's to the last bit (GPU 1e38 for infinity).
fn bit_identical(gpu: &Got, cpu: &Got) -> bool {
    let same = |g: f32, c: f32| g == c || (c.is_infinite() && g == c.signum() * GPU_INF);
    gpu.spans.len() == cpu.spans.len()
        && gpu
            .spans
            .iter()
            .zip(&cpu.spans)
            .all(|(g, c)| same(g.0, c.0) && same(g.1, c.1) && g.2 == c.2 && g.3 == c.3)
        && gpu.sdf == cpu.sdf
}

#[test]
fn gpu_torus_matches_cpu_twin() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let mut items = named();
    items.extend(families());
    // Every ray as given and recentred to its closest approach, as Leaf::step calls it.
    let recentred: Vec<Item> = items.iter().map(Item::recentred).collect();
    let raw_count = items.len();
    items.extend(recentred);
    let gpu = gpu_run(&ctx, &items);
    let mut bad = 0;
    let mut hits = 0;
    let mut identical = 0;
    for (k, (it, g)) in items.iter().zip(&gpu).enumerate() {
        let c = cpu_run(it);
        hits += !c.spans.is_empty() as usize;
        identical += bit_identical(g, &c) as usize;
        if let Some(why) = disagreement(it, g, &c) {
            bad += 1;
            if bad <= 20 {
                let kind = if k < raw_count { "raw" } else { "recentred" };
                eprintln!(
                    "{} ({kind}) {why}: {:?}\n  gpu {:?} sdf {}\n  cpu {:?} sdf {}",
                    it.family, it, g.spans, g.sdf, c.spans, c.sdf
                );
            }
        }
    }
    let rate = 1.0 - bad as f64 / items.len() as f64;
    eprintln!(
        "torus twin: {bad} of {} rays disagree ({:.4}% agree), {identical} bit-identical, \
         {hits} hit",
        items.len(),
        100.0 * rate
    );
    assert!(
        hits > items.len() / 3,
        "the sample must hit the tori ({hits})"
    );
    assert!(rate >= REQUIRED_RATE, "{bad} of {} disagree", items.len());
}
