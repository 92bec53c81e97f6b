//! Named hard cases where an f32 scan's surface tolerance would decide, checked in f32 and
//! f64 against answers written from the geometry in f64: rays starting within 1e-6 to
//! 1e-3 mm of a face (inward and outward, near the origin and 1e5 mm out), rays starting
//! on a face and running along it, grazing crossings of a large sphere, thin chords past
//! the edge of a long box, rays from inside a long thin tube (an optical fibre), and a
//! thin horn torus seen from metres away, and chords shorter than the tolerance through the
//! edge where two operands of a boolean solid meet, and a polycone's internal face crossed
//! at a shallow angle (a ray of CMS's `cmse.gdml`). An f32 scan answers these as f64 does:
//! it traces again in f64 the rays its trace flags (starts within its tolerance of a
//! surface, short spans dropped as touches), that cross at grazing incidence, or whose
//! crossing of a torus lies off the f64 surface (`scan::redo_flagged_in_f64`); each f32
//! test checks that the scan did so. On a GPU (lavapipe in CI) the kernel must give the
//! CPU's f32 trace bit for bit, flags included, and the f32 scan the CPU's.

mod common;

use common::{block_with_pit, f32_ray, gpu_run, rays_across_the_pit_edge, unit, Random, Rng};
use hytrace_csg::Ray;
use hytrace_csg::{box3, polyhedron, sphere, to_tree, torus, tube, Shape};
use hytrace_foundry::{Foundry, Transform64, TypeCode, UNSET};
use hytrace_trace::cpu::{CpuScene, STATUS_DROPPED_SPAN};
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::scan::{scan, scan_with, Backend, Precision, RayRow, ScanResult};

/// Tests `$case` in f32 and in f64, as `$f32` and `$f64`.
macro_rules! both_precisions {
    ($case:ident, $f32:ident, $f64:ident) => {
        #[test]
        fn $f32() {
            $case(Precision::F32);
        }

        #[test]
        fn $f64() {
            $case(Precision::F64);
        }
    };
}

/// A scene of one CSG solid placed by `at`.
fn placed(shape: Shape, at: Transform64) -> Foundry {
    let mut f = Foundry::new();
    let mut s = f.begin_solid("solid");
    s.add_csg(to_tree(&shape).unwrap(), 0, UNSET).unwrap();
    let solid = s.finish(0).unwrap();
    f.add_instance(solid, at, 0, 0).unwrap();
    f
}

/// A ray from `origin` along the unit `direction`, from 0 on.
fn row(origin: [f64; 3], direction: [f64; 3]) -> RayRow {
    RayRow {
        origin,
        direction,
        tmin: 0.0,
        tmax: f64::INFINITY,
    }
}

/// A uniformly random unit vector.
fn isotropic(rng: &mut Rng) -> [f64; 3] {
    let z = 2.0 * rng.uniform() - 1.0;
    let phi = std::f64::consts::TAU * rng.uniform();
    let r = (1.0 - z * z).sqrt();
    [r * phi.cos(), r * phi.sin(), z]
}

/// The scan of `rows` in precision `p`. In f32 it must have traced some rays again in f64
/// when `must_redo`, and where a GPU is found the GPU scan kernel must give the CPU's f32
/// trace bit for bit on every ray (the twins compared before any ray is traced again), and
/// the GPU scan the CPU's f32 scan.
fn scanned(f: &Foundry, rows: &[RayRow], p: Precision, must_redo: bool) -> ScanResult {
    let (result, times) = scan(f, rows, p).unwrap();
    if p == Precision::F64 {
        return result;
    }
    eprintln!(
        "{} of {} rays traced again in f64",
        times.redone_in_f64,
        rows.len()
    );
    assert!(
        !must_redo || times.redone_in_f64 > 0,
        "no ray was traced again in f64"
    );
    let Some(ctx) = GpuContext::for_tests() else {
        return result;
    };
    let kernel = gpu_run(&ctx, f, rows).unwrap();
    assert_eq!(kernel.cut_short, 0, "a ray was cut short");
    let cpu = CpuScene::<f32>::new(f).unwrap();
    for (i, (r, (g, &g_flags))) in rows
        .iter()
        .zip(kernel.hits.iter().zip(&kernel.flags))
        .enumerate()
    {
        let (_, tmin, tmax) = f32_ray(r);
        let c = cpu.trace_flagged(&Ray::from_f64(r.origin, r.direction), tmin, tmax);
        let c = (
            c.hit
                .map(|h| (h.t.to_bits(), h.normal.to_f64(), h.instance)),
            c.flags,
        );
        let g = (
            g.map(|h| (h.t.to_bits(), h.normal.to_f64(), h.instance)),
            g_flags,
        );
        assert_eq!(c, g, "GPU kernel, ray {i} {r:?}");
    }
    let (gpu, _) = scan_with(f, rows, p, Backend::Gpu).unwrap();
    for (i, r) in rows.iter().enumerate() {
        let same = result.hits[i]
            .iter()
            .zip(&gpu.hits[i])
            .all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(
            same && result.ids[i] == gpu.ids[i],
            "GPU scan, ray {i} {r:?}: {:?} {:?}, CPU {:?} {:?}",
            gpu.hits[i],
            gpu.ids[i],
            result.hits[i],
            result.ids[i]
        );
    }
    result
}

/// Checks every answer against `want` within `tolerance(row, want)`, listing the first
/// disagreements.
fn check(
    name: &str,
    rows: &[RayRow],
    got: &ScanResult,
    want: &[f64],
    tolerance: impl Fn(&RayRow, f64) -> f64,
) {
    let mut wrong = Vec::new();
    for (i, (r, &w)) in rows.iter().zip(want).enumerate() {
        let g = got.hits[i][3];
        let ok = (g.is_infinite() && w.is_infinite()) || (g - w).abs() <= tolerance(r, w);
        if !ok {
            wrong.push(format!("ray {i} {r:?}: {g}, exact {w}"));
        }
    }
    assert!(
        wrong.is_empty(),
        "{name}: {} of {} rays wrong, e.g.\n{}",
        wrong.len(),
        rows.len(),
        wrong[..wrong.len().min(5)].join("\n")
    );
}

/// The oracle tests' tolerance: 2e-6 of the origin's distance from the world origin plus
/// the distance travelled, at least 1e-9 mm.
fn relative(r: &RayRow, t: f64) -> f64 {
    let o = r.origin.iter().map(|c| c * c).sum::<f64>().sqrt();
    (2e-6 * (o + if t.is_finite() { t } else { 0.0 })).max(1e-9)
}

/// Where a ray from `o` along `d` first leaves (`inside`) or enters the axis-aligned box
/// of half sides `h` centred on the origin: slab intersection in f64.
fn box_distance(h: [f64; 3], o: [f64; 3], d: [f64; 3]) -> f64 {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        if d[k] == 0.0 {
            if o[k].abs() > h[k] {
                return f64::INFINITY;
            }
            continue;
        }
        let (a, b) = ((-h[k] - o[k]) / d[k], (h[k] - o[k]) / d[k]);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    match () {
        _ if t0 > t1 || t1 <= 0.0 => f64::INFINITY,
        _ if t0 > 0.0 => t0,
        _ => t1,
    }
}

/// Half sides of the 2 x 1 x 0.5 m box of the near-surface cases (f32 tolerance there:
/// 2e-3 mm).
const BOX: [f64; 3] = [1000.0, 500.0, 250.0];

/// `count` rays `ray(rng, i)` (a start in the box's frame and a direction) traced through
/// the box placed at the origin and 1e5 mm out, against the exact slab answer.
fn box_cases(
    name: &str,
    p: Precision,
    seed: u64,
    count: usize,
    mut ray: impl FnMut(&mut Rng, usize) -> ([f64; 3], [f64; 3]),
) {
    for distance in [0.0, 1e5] {
        let at = [0.6, -0.48, 0.64].map(|c| c * distance);
        let size = BOX.map(|h| 2.0 * h);
        let f = placed(
            box3(size[0], size[1], size[2]).unwrap(),
            Transform64::translation(at),
        );
        let mut rng = Rng(seed + distance as u64);
        let (mut rows, mut want) = (Vec::new(), Vec::new());
        for i in 0..count {
            let (local, d) = ray(&mut rng, i);
            rows.push(row([0, 1, 2].map(|k| at[k] + local[k]), d));
            want.push(box_distance(BOX, local, d));
        }
        let got = scanned(&f, &rows, p, true);
        check(
            &format!("{name} at {distance} mm"),
            &rows,
            &got,
            &want,
            relative,
        );
    }
}

/// 1e-6 to 1e-3 mm, alternately outward and inward.
fn offset(rng: &mut Rng, i: usize) -> f64 {
    10f64.powf(-6.0 + 3.0 * rng.uniform()) * if i.is_multiple_of(2) { 1.0 } else { -1.0 }
}

/// Rays starting 1e-6 to 1e-3 mm off a face of the box, inward and outward, isotropic: the
/// entry just ahead (or the exit through the face just behind) is a crossing, not the
/// surface the ray starts on.
fn near_surface_starts(p: Precision) {
    box_cases("near a face", p, 7, 4000, |rng, i| {
        let axis = i % 3;
        let side = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        let off = offset(rng, i);
        let mut local = [0, 1, 2].map(|k| BOX[k] * (2.0 * rng.uniform() - 1.0) * 0.9);
        local[axis] = side * (BOX[axis] + off);
        (local, isotropic(rng))
    });
}

both_precisions!(
    near_surface_starts,
    near_surface_starts_f32,
    near_surface_starts_f64
);

/// Rays starting 1e-6 to 1e-3 mm inside or outside the top face of the box and running
/// along it: inside they leave through a side, outside they miss. Which side of the face
/// the start lies on decides, within f32 rounding of the start.
fn along_a_face(p: Precision) {
    box_cases("along a face", p, 11, 2000, |rng, i| {
        let off = offset(rng, i);
        let local = [
            BOX[0] * (2.0 * rng.uniform() - 1.0) * 0.9,
            BOX[1] * (2.0 * rng.uniform() - 1.0) * 0.9,
            BOX[2] - off,
        ];
        let phi = std::f64::consts::TAU * rng.uniform();
        (local, [phi.cos(), phi.sin(), 0.0])
    });
}

both_precisions!(along_a_face, along_a_face_f32, along_a_face_f64);

/// Rays from 1.5 m passing a sphere of radius 1 m at 0.001 to 30 mm inside its rim (half
/// chords of 1.4 to 245 mm): near tangency the f32 root is off by the sphere's size times
/// epsilon over the cosine of incidence, which the scan must not let through.
fn grazing_sphere(p: Precision) {
    let radius = 1000.0;
    let f = placed(sphere(radius).unwrap(), Transform64::IDENTITY);
    let mut rng = Rng(13);
    let (mut rows, mut want) = (Vec::new(), Vec::new());
    for _ in 0..3000 {
        let d = isotropic(&mut rng);
        // A unit vector across `d`.
        let a = if d[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let dot = a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
        let u = unit([0, 1, 2].map(|k| a[k] - dot * d[k]));
        let pass = radius - 10f64.powf(-3.0 + 4.5 * rng.uniform());
        let origin = [0, 1, 2].map(|k| -1500.0 * d[k] + pass * u[k]);
        rows.push(row(origin, d));
        want.push(1500.0 - (radius * radius - pass * pass).sqrt());
    }
    let got = scanned(&f, &rows, p, true);
    check("grazing sphere", &rows, &got, &want, relative);
}

both_precisions!(grazing_sphere, grazing_sphere_f32, grazing_sphere_f64);

/// A box 9.5 x 90000 x 27 mm (a long bar, f32 tolerance 0.09 mm) crossed near an edge
/// along its length by rays whose chord inside it is 0.028 to 0.09 mm: a thin part of a
/// planar solid, not a tangent touch.
fn thin_chord_of_a_long_box(p: Precision) {
    let h = [4.75, 45000.0, 13.5];
    let f = placed(box3(9.5, 90000.0, 27.0).unwrap(), Transform64::IDENTITY);
    let mut rng = Rng(17);
    let (mut rows, mut want) = (Vec::new(), Vec::new());
    for _ in 0..2000 {
        // In the xz plane, at 45 degrees past the corner (h_x, h_z), cutting the corner by
        // a chord of length c: the line x + z = h_x + h_z - c / sqrt(2).
        let c = 10f64.powf(-1.55 + 0.5 * rng.uniform());
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let y = h[1] * (2.0 * rng.uniform() - 1.0) * 0.9;
        let along = 0.2 * (2.0 * rng.uniform() - 1.0);
        let d = unit([s, along, -s]);
        let back = 50.0;
        let corner = [h[0] - c * s * s, y, h[2] - c * s * s];
        let origin = [0, 1, 2].map(|k| corner[k] - back * d[k]);
        rows.push(row(origin, d));
        want.push(box_distance(h, origin, d));
    }
    let got = scanned(&f, &rows, p, false);
    check("thin chords", &rows, &got, &want, relative);
}

both_precisions!(
    thin_chord_of_a_long_box,
    thin_chord_of_a_long_box_f32,
    thin_chord_of_a_long_box_f64
);

/// Rays from inside an optical fibre (a tube of radius 0.1825 mm and length 1 m, f32
/// tolerance 1e-3 mm) at up to 400 mm from its middle, isotropic: the exit through the
/// wall, within 1e-5 mm plus 2e-6 of the distance, as exact as the fibre's radius allows
/// (the error must not grow with the start's distance along the fibre).
fn inside_a_long_thin_tube(p: Precision) {
    let (r, half) = (0.1825, 500.0);
    let f = placed(tube(0.0, r, -half, half).unwrap(), Transform64::IDENTITY);
    let mut rng = Rng(19);
    let (mut rows, mut want) = (Vec::new(), Vec::new());
    for _ in 0..3000 {
        let rho = r * rng.uniform().sqrt() * 0.99;
        let phi = std::f64::consts::TAU * rng.uniform();
        let o = [
            rho * phi.cos(),
            rho * phi.sin(),
            400.0 * (2.0 * rng.uniform() - 1.0),
        ];
        let d = isotropic(&mut rng);
        // The exit: the wall's root of |o_xy + t d_xy| = r, or a cap.
        let (a, b) = (d[0] * d[0] + d[1] * d[1], o[0] * d[0] + o[1] * d[1]);
        let c = o[0] * o[0] + o[1] * o[1] - r * r;
        let wall = if a > 0.0 {
            (-b + (b * b - a * c).sqrt()) / a
        } else {
            f64::INFINITY
        };
        let cap = if d[2] != 0.0 {
            ((half * d[2].signum()) - o[2]) / d[2]
        } else {
            f64::INFINITY
        };
        rows.push(row(o, d));
        want.push(wall.min(cap));
    }
    let got = scanned(&f, &rows, p, true);
    check("fibre", &rows, &got, &want, |_, t| 1e-5 + 2e-6 * t);
}

both_precisions!(
    inside_a_long_thin_tube,
    inside_a_long_thin_tube_f32,
    inside_a_long_thin_tube_f64
);

/// A field-shaper tube of DUNE's vertical drift detector: a 9 m aluminium pipe (radii 5
/// and 22.85 mm) with a horn torus corner (22.85 mm about a 23 mm circle) at its end,
/// placed 4.5 m out and turned by 30 degrees, hit by rays from 6 m away aimed at the
/// corner. In f32 against the f64 scan (itself checked against Geant4 on the oracle tests'
/// tori), whose hit points lie on the torus or the pipe to 1e-9 mm.
fn horn_torus_from_afar(p: Precision) {
    let (rmin, rmax, rtor, half) = (5.0, 22.85, 23.0, 4482.6);
    let corner = Transform64::translation([-rtor, 0.0, half]).compose(&Transform64::rotation(
        [1.0, 0.0, 0.0],
        std::f64::consts::FRAC_PI_2,
    ));
    let shape = Shape::Op(
        TypeCode::Union,
        Box::new(tube(rmin, rmax, -half, half).unwrap()),
        Box::new(torus(rmin, rmax, rtor).unwrap().placed(corner)),
    );
    let place = Transform64::translation([0.4, 0.0, 4482.6]).compose(&Transform64::rotation(
        [0.0, 1.0, 0.0],
        std::f64::consts::PI / 6.0,
    ));
    let f = placed(shape, place);
    let aim_at = place.apply_point(corner.apply_point([0.0; 3]));
    let mut rng = Rng(23);
    let rows: Vec<RayRow> = (0..4000)
        .map(|_| {
            let d = isotropic(&mut rng);
            let target: [f64; 3] =
                std::array::from_fn(|k| aim_at[k] + 50.0 * (2.0 * rng.uniform() - 1.0));
            row([0, 1, 2].map(|k| target[k] - 6000.0 * d[k]), d)
        })
        .collect();
    let (exact, _) = scan(&f, &rows, Precision::F64).unwrap();
    // The f64 answers lie on the pipe or the torus.
    let (to_solid, to_corner) = (place.inverse().unwrap(), corner.inverse().unwrap());
    let mut hits = 0;
    for (r, h) in rows
        .iter()
        .zip(&exact.hits)
        .filter(|(_, h)| h[3].is_finite())
    {
        let x: [f64; 3] = std::array::from_fn(|k| r.origin[k] + h[3] * r.direction[k]);
        let s = to_solid.apply_point(x);
        let rho = (s[0] * s[0] + s[1] * s[1]).sqrt();
        let on_pipe = s[2].abs() <= half + 1e-9
            && ((rho - rmax).abs() < 1e-9
                || (rho - rmin).abs() < 1e-9
                || (s[2].abs() - half).abs() < 1e-9);
        let c = to_corner.apply_point(s);
        let tube_r = (((c[0] * c[0] + c[1] * c[1]).sqrt() - rtor).powi(2) + c[2] * c[2]).sqrt();
        let on_torus = (tube_r - rmax).abs() < 1e-9 || (tube_r - rmin).abs() < 1e-9;
        assert!(
            on_pipe || on_torus,
            "f64 answer off the surface: {r:?} {h:?}"
        );
        hits += 1;
    }
    assert!(hits > 1000, "{hits} hits");
    let want: Vec<f64> = exact.hits.iter().map(|h| h[3]).collect();
    let got = if p == Precision::F32 {
        scanned(&f, &rows, p, true)
    } else {
        exact
    };
    check("field shaper corner", &rows, &got, &want, relative);
}

both_precisions!(
    horn_torus_from_afar,
    horn_torus_from_afar_f32,
    horn_torus_from_afar_f64
);

/// How many of `rows` the plain f32 trace of `f` flags as passing a dropped span, checking
/// that it answers every other one within the oracle's tolerance of `want`.
fn flagged_or_right(f: &Foundry, rows: &[RayRow], want: &[f64]) -> usize {
    let cpu = CpuScene::<f32>::new(f).unwrap();
    let mut flagged = 0;
    for (i, r) in rows.iter().enumerate() {
        let (_, tmin, tmax) = f32_ray(r);
        let traced = cpu.trace_flagged(&Ray::from_f64(r.origin, r.direction), tmin, tmax);
        let t = traced.hit.map_or(f64::INFINITY, |h| f64::from(h.t));
        let dropped = traced.flags & STATUS_DROPPED_SPAN != 0;
        flagged += usize::from(dropped);
        assert!(
            dropped || (t - want[i]).abs() <= relative(r, want[i]),
            "ray {i} {r:?}: f32 {t}, exact {}, not flagged",
            want[i]
        );
    }
    eprintln!("{flagged} of {} rays flagged", rows.len());
    flagged
}

/// Rays crossing the wall of [`block_with_pit`] 1e-4 to 2e-3 mm below the top face: chords
/// of 2e-4 to 4e-3 mm, under the f32 tolerance there (4.4e-3 mm, so the tree merges the
/// wall's and the top's crossings and drops the chord) and over the rounding of `t` there
/// (1.5e-5 mm). Without the trace flagging the dropped chord, the f32 scan misses the
/// block.
fn chord_through_a_boolean_edge(p: Precision) {
    let f = block_with_pit();
    let rows = rays_across_the_pit_edge(23, 400, [-4.0, -2.7]);
    let want = vec![200.0; rows.len()];
    if p == Precision::F32 {
        // Every ray the plain f32 trace gets wrong is flagged (the longer chords it keeps).
        let flagged = flagged_or_right(&f, &rows, &want);
        assert!(flagged > rows.len() / 2, "{flagged} rays flagged");
    }
    let got = scanned(&f, &rows, p, true);
    check(
        "chords through a boolean edge",
        &rows,
        &got,
        &want,
        relative,
    );
}

both_precisions!(
    chord_through_a_boolean_edge,
    chord_through_a_boolean_edge_f32,
    chord_through_a_boolean_edge_f64
);

/// Chords under one ulp of `t` through the edge of [`block_with_pit`]: rays crossing its
/// wall 1e-7 to 3e-6 mm below the top face, 200 mm from their start (f32 spacing there:
/// 1.5e-5 mm), so that both ends of most chords round to one f32 `t` (as the ends of a face
/// two operands share do) or to the wrong order; f64 (tolerance 1.2e-8 mm here) keeps them
/// all. The trace tells them apart by the surfaces' normals: the wall and the top meet at a
/// right angle, shared faces are parallel. The plain f32 trace flags every ray it gets wrong and the scan
/// answers the exact entry; rays across the face that two boxes of a union share, at the
/// same parameters and angles, are never flagged. The GPU kernel gives the CPU's flags bit
/// for bit.
#[test]
fn chords_under_one_ulp_are_traced_in_f64() {
    let f = block_with_pit();
    let rows = rays_across_the_pit_edge(29, 400, [-7.0, -5.5]);
    let want = vec![200.0; rows.len()];
    let flagged = flagged_or_right(&f, &rows, &want);
    assert!(flagged > rows.len() / 2, "{flagged} rays flagged");
    for p in [Precision::F32, Precision::F64] {
        let got = scanned(&f, &rows, p, p == Precision::F32);
        check("chords under one ulp of t", &rows, &got, &want, relative);
    }
    // The block as two convex halves split at x = 200 (the pit's wall extended), the same
    // rays 100 mm lower: both halves meet the face they share at one parameter, to the bit,
    // with parallel normals; crossing it changes nothing, the top is the exit, and no ray
    // is flagged.
    let half = |x0: f64, x1: f64| {
        polyhedron(&[
            [1.0, 0.0, 0.0, x1],
            [-1.0, 0.0, 0.0, -x0],
            [0.0, 1.0, 0.0, 1000.0],
            [0.0, -1.0, 0.0, 1000.0],
            [0.0, 0.0, 1.0, 500.0],
            [0.0, 0.0, -1.0, 500.0],
        ])
        .unwrap()
    };
    let f = placed(
        half(-1000.0, 200.0) + half(200.0, 1000.0),
        Transform64::IDENTITY,
    );
    let rows: Vec<RayRow> = rows
        .iter()
        .map(|r| row([r.origin[0], r.origin[1], r.origin[2] - 100.0], r.direction))
        .collect();
    let block = [1000.0, 1000.0, 500.0];
    let want: Vec<f64> = rows
        .iter()
        .map(|r| box_distance(block, r.origin, r.direction))
        .collect();
    assert_eq!(flagged_or_right(&f, &rows, &want), 0);
    let got = scanned(&f, &rows, Precision::F32, false);
    check("rays across a shared face", &rows, &got, &want, relative);
}

/// The polycone `TotemT1` of CMS (`celeritas/cmse.gdml`): hollow pieces from z = 7499 mm
/// to 10500 mm, a cone frustum of outer radius 814 mm at z = 7950 mm to 1041.1 mm at
/// z = 10165 mm under a cylinder of radius 1130 mm from there; the plane z = 10165 mm is a
/// face the two pieces share, inside the solid.
fn totem_t1() -> Shape {
    use hytrace_csg::geant4::{G4Mapping, G4Solid};
    G4Solid::Polycone {
        sphi: 0.0,
        dphi: std::f64::consts::TAU,
        z: vec![7499.0, 7950.0, 7950.0, 10165.0, 10165.0, 10500.0],
        rmin: vec![117.85, 121.5, 122.0, 154.1, 154.1, 159.0],
        rmax: vec![768.0, 814.0, 814.0, 1041.1, 1130.0, 1130.0],
    }
    .to_shape()
    .unwrap()
}

/// Where a ray from `o` along the unit `d`, inside the cone of [`totem_t1`]'s middle piece
/// (extended past its caps), leaves that cone: the larger root of the quadratic, in f64.
fn totem_t1_cone_exit(o: [f64; 3], d: [f64; 3]) -> f64 {
    let k = (1041.1 - 814.0) / (10165.0 - 7950.0);
    let r0 = 814.0 + k * (o[2] - 7950.0);
    let a = d[0] * d[0] + d[1] * d[1] - k * k * d[2] * d[2];
    let b = o[0] * d[0] + o[1] * d[1] - k * d[2] * r0;
    let c = o[0] * o[0] + o[1] * o[1] - r0 * r0;
    (-b + (b * b - a * c).sqrt()) / a
}

/// Rays from inside the top piece of the polycone [`totem_t1`], moving outward and down
/// across the face z = 10165 mm that its top two pieces share, at 7 to 17 degrees to it,
/// to leave through the middle piece's cone: ray 8996 of the GDML oracle's `cmse.gdml`
/// sample (Geant4: 916.7113927192937 mm) and 400 like it. The f32 cone met its cap from
/// the ray's origin moved to the cone's centre, rounded at the frame's coordinates (z about
/// 10^4 mm) where the cylinder met the same plane from the origin itself: over the cosine
/// of 0.131 the two crossings of the face came 3.7e-3 mm apart, over the tolerance, and
/// the plain f32 trace answered the face (93.8 mm) as an exit, unflagged. Both now meet
/// shared caps from the unmoved origin, to the same bits: the plain f32 trace must answer
/// right on every ray, flagged or not.
fn polycone_face_at_a_shallow_angle(p: Precision) {
    let f = placed(totem_t1(), Transform64::IDENTITY);
    let mut rows = vec![row(
        [249.32925415039062, -44.159305572509766, 10177.3037109375],
        [
            0.20207668687199148,
            -0.9705437803022788,
            -0.13118606305321087,
        ],
    )];
    let mut rng = Rng(8996);
    while rows.len() < 401 {
        let (r0, phi) = (
            200.0 + 700.0 * rng.uniform(),
            std::f64::consts::TAU * rng.uniform(),
        );
        let z0 = 10165.0 + 10f64.powf(-0.3 + 1.5 * rng.uniform());
        let cos = 0.12 + 0.18 * rng.uniform();
        let heading = phi + (2.0 * rng.uniform() - 1.0) * 60f64.to_radians();
        let across = (1.0 - cos * cos).sqrt();
        let d = [across * heading.cos(), across * heading.sin(), -cos];
        rows.push(row([r0 * phi.cos(), r0 * phi.sin(), z0], d));
    }
    let want: Vec<f64> = rows
        .iter()
        .map(|r| totem_t1_cone_exit(r.origin, r.direction))
        .collect();
    assert!((want[0] - 916.7113927192937).abs() < 1e-9, "{}", want[0]);
    if p == Precision::F32 {
        let cpu = CpuScene::<f32>::new(&f).unwrap();
        for (i, r) in rows.iter().enumerate() {
            let (_, tmin, tmax) = f32_ray(r);
            let traced = cpu.trace_flagged(&Ray::from_f64(r.origin, r.direction), tmin, tmax);
            let t = traced.hit.map_or(f64::INFINITY, |h| f64::from(h.t));
            assert!(
                (t - want[i]).abs() <= relative(r, want[i]),
                "ray {i} {r:?}: plain f32 trace {t}, exact {}",
                want[i]
            );
        }
    }
    let got = scanned(&f, &rows, p, false);
    check(
        "a polycone's shared face at a shallow angle",
        &rows,
        &got,
        &want,
        relative,
    );
}

both_precisions!(
    polycone_face_at_a_shallow_angle,
    polycone_face_at_a_shallow_angle_f32,
    polycone_face_at_a_shallow_angle_f64
);

/// Half side of the mesh cube of the mesh cases (mm).
const CUBE: f64 = 10.0;

/// A scene of one cube mesh of half side [`CUBE`] (12 triangles, counter-clockwise seen
/// from outside) placed by a translation to `at`.
fn cube_mesh(at: [f64; 3]) -> Foundry {
    let mut triangles = Vec::new();
    for k in 0..3 {
        let (u, v) = ((k + 1) % 3, (k + 2) % 3);
        for side in [-1.0f32, 1.0] {
            // Corners counter-clockwise about +axis k (e_u x e_v = e_k), reversed for -k.
            let mut quad = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(a, b)| {
                let mut p = [0.0f32; 4];
                p[k] = side * CUBE as f32;
                p[u] = a * CUBE as f32;
                p[v] = b * CUBE as f32;
                p
            });
            if side < 0.0 {
                quad.reverse();
            }
            for [i, j, l] in [[0, 1, 2], [0, 2, 3]] {
                triangles.push(hytrace_foundry::Triangle {
                    v: [quad[i], quad[j], quad[l]],
                });
            }
        }
    }
    let mut f = Foundry::new();
    let mut s = f.begin_solid("cube");
    s.add_mesh(&triangles, None, 0, UNSET).unwrap();
    let solid = s.finish(0).unwrap();
    f.add_instance(solid, Transform64::translation(at), 0, 0)
        .unwrap();
    f
}

/// A unit vector near `d` that is its own f32 unit vector: rounded to f32, normalized in
/// f64 and rounded again it is unchanged, so the f32 trace (which rounds directions) and
/// the f64 references trace the same ray.
fn own_unit_f32(d: [f64; 3], rng: &mut Rng) -> [f64; 3] {
    let want = unit(d);
    let mut r = want.map(|c| c as f32);
    loop {
        let again = unit(r.map(f64::from)).map(|c| c as f32);
        if again == r {
            return r.map(f64::from);
        }
        r = unit(want.map(|c| c * (1.0 + 1e-7 * (2.0 * rng.uniform() - 1.0)))).map(|c| c as f32);
    }
}

/// The mesh accuracy tolerance of issue 30 (`mesh_oracle.rs`): 4e-7 of the origin's
/// largest coordinate plus the distance travelled.
fn mesh_tolerance(r: &RayRow, t: f64) -> f64 {
    let o = r.origin.iter().fold(0.0f64, |a, c| a.max(c.abs()));
    4e-7 * (o + if t.is_finite() { t } else { 0.0 })
}

/// `count` rays `ray(rng, i)` (a start in the cube's frame and a direction, which is made
/// its own f32 unit vector) traced through the mesh cube placed at the origin and 1e5 mm
/// out, against the exact slab answer of the cube, within [`mesh_tolerance`]. In f32, the
/// plain trace (no fallback) must be wrong on some of them (at the origin: 1e5 mm out the
/// tolerance is that distance's, and f32 in the cube's frame is well within it): the
/// scan's f64 fallback is what makes them right.
fn mesh_cube_cases(
    name: &str,
    p: Precision,
    seed: u64,
    count: usize,
    mut ray: impl FnMut(&mut Rng, usize) -> ([f64; 3], [f64; 3]),
) {
    let h = [CUBE; 3];
    for distance in [0.0, 1e5] {
        let at = [0.6, -0.48, 0.64].map(|c| c * distance);
        let f = cube_mesh(at);
        let mut rng = Rng(seed + distance as u64);
        let (mut rows, mut want) = (Vec::new(), Vec::new());
        for i in 0..count {
            let (local, d) = ray(&mut rng, i);
            let d = own_unit_f32(d, &mut rng);
            let origin = [0, 1, 2].map(|k| at[k] + local[k]);
            // The cube's frame as the trace rebases into it (the same f64 subtraction).
            let local = [0, 1, 2].map(|k| origin[k] - at[k]);
            rows.push(row(origin, d));
            want.push(box_distance(h, local, d));
        }
        let label = format!("{name} at {distance} mm");
        if p == Precision::F32 {
            let cpu = CpuScene::<f32>::new(&f).unwrap();
            let plain_wrong = rows
                .iter()
                .zip(&want)
                .filter(|(r, &w)| {
                    let (_, tmin, tmax) = f32_ray(r);
                    let hit = cpu.trace(&Ray::from_f64(r.origin, r.direction), tmin, tmax);
                    let t = hit.map_or(f64::INFINITY, |h| f64::from(h.t));
                    !((t.is_infinite() && w.is_infinite()) || (t - w).abs() <= mesh_tolerance(r, w))
                })
                .count();
            eprintln!("{label}: the plain f32 trace is wrong on {plain_wrong} rays");
            assert!(
                distance > 0.0 || plain_wrong > 0,
                "{label}: no ray is hard for f32"
            );
        }
        let got = scanned(&f, &rows, p, true);
        check(&label, &rows, &got, &want, mesh_tolerance);
    }
}

/// A random point of a random edge (a vertex on every fourth ray) of the cube.
fn cube_edge_point(rng: &mut Rng, i: usize) -> [f64; 3] {
    let axis = i % 3;
    let mut p = [0, 1, 2].map(|_| if rng.uniform() < 0.5 { -CUBE } else { CUBE });
    if !i.is_multiple_of(4) {
        p[axis] = CUBE * (2.0 * rng.uniform() - 1.0);
    }
    p
}

/// Rays from every direction passing 1e-9 to 1e-5 of the cube's size beside its edges and
/// vertices (inside or outside): where a silhouette edge is, the f32 triangle test's hit or
/// miss is within rounding, and so, through a shared edge, is which face is crossed.
fn mesh_edges_and_vertices(p: Precision) {
    mesh_cube_cases("mesh edges and vertices", p, 29, 3000, |rng, i| {
        let target = cube_edge_point(rng, i);
        let d = isotropic(rng);
        let side = unit(isotropic(rng));
        // `side` made perpendicular to d.
        let dot: f64 = (0..3).map(|k| side[k] * d[k]).sum();
        let across = unit([0, 1, 2].map(|k| side[k] - dot * d[k]));
        let off = 2.0 * CUBE * 10f64.powf(-9.0 + 4.0 * rng.uniform());
        let start = 3.0 * CUBE;
        (
            [0, 1, 2].map(|k| target[k] + off * across[k] - start * d[k]),
            d,
        )
    });
}

both_precisions!(
    mesh_edges_and_vertices,
    mesh_edges_and_vertices_f32,
    mesh_edges_and_vertices_f64
);

/// Rays meeting a face of the cube at 0.5 to 8 degrees from its plane, at random points
/// (some beside an edge): the f32 distance along a shallow crossing is off by the
/// rounding of the coordinates over the sine of the angle.
fn grazing_mesh_facets(p: Precision) {
    mesh_cube_cases("grazing mesh facets", p, 31, 3000, |rng, i| {
        let axis = i % 3;
        let sign = if rng.uniform() < 0.5 { -1.0 } else { 1.0 };
        let mut target = [0, 1, 2].map(|_| CUBE * (2.0 * rng.uniform() - 1.0));
        target[axis] = sign * CUBE;
        // A direction `angle` below the face's plane, heading into the cube.
        let angle = (0.5 + 7.5 * rng.uniform()).to_radians();
        let phi = std::f64::consts::TAU * rng.uniform();
        let mut d = [0.0; 3];
        d[(axis + 1) % 3] = angle.cos() * phi.cos();
        d[(axis + 2) % 3] = angle.cos() * phi.sin();
        d[axis] = -sign * angle.sin();
        let start = 3.0 * CUBE;
        ([0, 1, 2].map(|k| target[k] - start * d[k]), d)
    });
}

both_precisions!(
    grazing_mesh_facets,
    grazing_mesh_facets_f32,
    grazing_mesh_facets_f64
);
