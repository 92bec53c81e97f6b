//! Accuracy rows of the CSG kernels: f32 against f64, the far-from-origin strategy on and
//! off, the quadratic (sphere) solver and the torus's crossing search, list nodes against binary
//! trees. References are double-double evaluations of the exact surfaces ([`super::dd`]),
//! for the very f32-representable rays the kernels see.
//!
//! The far-from-origin strategy is the one every leaf uses: before solving, the ray's
//! origin moves along the ray to its closest approach to the primitive's centre, so the
//! quadric or torus has coefficients of the primitive's size however far the ray starts.
//! "Off" solves at the ray's own origin, as a textbook intersection does. The torus's
//! crossing search moves the origin to the closest approach itself, so for the torus "off"
//! only shows that the leaf's shift costs nothing there.

use hytrace_csg::kernel::{first_crossing, primitive_spans, Frame, Leaf};
use hytrace_csg::{sphere, to_tree_with, PrimTree, Ray, Real, Shape, TreeOptions};
use hytrace_foundry::{Node, Transform64, TypeCode};
use hytrace_volume::Rng;

use super::dd::{self, Dd, DdVec};
use super::{Row, Settings, Timer};

/// Sphere radius and torus swept radius (mm).
pub(super) const RADIUS: f64 = 100.0;
/// Torus tube radius (mm).
pub(super) const TUBE: f64 = 20.0;
/// How far the rays start from the solid (mm).
const DISTANCES: [f64; 3] = [1e3, 2e4, 1e6];
/// Error counted for a ray whose hit or miss disagrees with the reference (mm).
const WRONG_HIT: f64 = 2.0 * RADIUS;
/// The metric of every CSG row.
const METRIC: &str = "max |t - t_ref| (mm); a wrong hit or miss counts 200";

/// A ray whose coordinates are f32 values, so both precisions see the same ray.
#[derive(Clone, Copy, Debug)]
pub(super) struct Case {
    pub(super) origin: [f64; 3],
    pub(super) dir: [f64; 3],
}

impl Case {
    fn ray<T: Real>(&self) -> Ray<T> {
        Ray::from_f64(self.origin, self.dir)
    }
}

fn round32(v: [f64; 3]) -> [f64; 3] {
    v.map(|c| c as f32 as f64)
}

/// A uniform point of the ball of radius `r`.
pub(super) fn in_ball(rng: &mut Rng, r: f64) -> [f64; 3] {
    loop {
        let p: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0);
        if p.iter().map(|c| c * c).sum::<f64>() <= 1.0 {
            return p.map(|c| c * r);
        }
    }
}

/// A ray from near the world origin toward `target`, rounded to f32.
fn aimed(rng: &mut Rng, target: [f64; 3]) -> Case {
    let origin = round32(in_ball(rng, 20.0));
    let d: [f64; 3] = std::array::from_fn(|k| target[k] - origin[k]);
    let n = d.iter().map(|c| c * c).sum::<f64>().sqrt();
    Case {
        origin,
        dir: round32(d.map(|c| c / n)),
    }
}

/// Where a solid `distance` away from the world origin is centred (f32 values).
fn centre_at(distance: f64) -> [f64; 3] {
    round32([0.48 * distance, 0.6 * distance, 0.64 * distance])
}

/// The first crossing after 0 of one leaf, with the strategy on (the ray's origin moved to
/// its closest approach to the primitive's centre before solving, as [`Leaf::step`] does)
/// or off (solved at the ray's origin). Both paths share everything else, so the time
/// difference is the strategy's.
fn leaf_crossing<T: Real>(leaf: &Leaf<T>, case: &Case, strategy: bool) -> Option<f64> {
    let ray = case.ray::<T>();
    let local = leaf.frame.as_ref().map_or(ray, |f| f.ray_to_local(&ray));
    let d = local.direction;
    let shift = if strategy {
        -local.origin.dot(d) / d.length_squared()
    } else {
        T::ZERO
    };
    let spans = primitive_spans(leaf.code, &leaf.params, &[], local.origin, d, shift);
    let step = first_crossing(&spans, shift, d, T::ZERO, T::ZERO, T::ZERO, 0);
    step.is_hit().then(|| step.t.to_f64())
}

/// The worst disagreement of `got` with `want` (see [`METRIC`]).
fn max_error(got: &[Option<f64>], want: &[Option<f64>]) -> f64 {
    got.iter()
        .zip(want)
        .map(|(g, w)| match (g, w) {
            (Some(g), Some(w)) => (g - w).abs(),
            (None, None) => 0.0,
            _ => WRONG_HIT,
        })
        .fold(0.0, f64::max)
}

/// The ray's entry and exit parameters of a sphere, in double-double.
fn dd_sphere(case: &Case, centre: [f64; 3], radius: f64) -> Option<(Dd, Dd)> {
    let (o, d) = (dd::vec(case.origin), dd::vec(case.dir));
    let oc = dd::sub(o, dd::vec(centre));
    let a = dd::dot(d, d);
    let b = dd::dot(oc, d);
    let c = dd::dot(oc, oc) - Dd::new(radius) * Dd::new(radius);
    let disc = b * b - a * c;
    if disc.is_negative() {
        return None;
    }
    let root = disc.sqrt();
    Some(((-b - root).div(a), (-b + root).div(a)))
}

/// The first sphere crossing after 0, in double-double.
pub(super) fn sphere_reference(case: &Case, centre: [f64; 3], radius: f64) -> Option<f64> {
    let (t0, t1) = dd_sphere(case, centre, radius)?;
    [t0, t1].into_iter().map(Dd::to_f64).find(|t| *t > 0.0)
}

/// The torus function `(|p|^2 + R^2 - r^2)^2 - 4 R^2 (x^2 + y^2)` (positive outside) at
/// `p = oc + t d`, in double-double.
fn torus_function(oc: DdVec, d: DdVec, t: f64) -> Dd {
    let p = dd::at(oc, d, Dd::new(t));
    let (big, small) = (Dd::new(RADIUS), Dd::new(TUBE));
    let s = dd::dot(p, p) + big * big - small * small;
    let radial = p[0] * p[0] + p[1] * p[1];
    s * s - Dd::new(4.0) * big * big * radial
}

/// The first torus crossing after 0: the torus function sampled finely across the
/// bounding sphere, its first change of sign (from the sign where the ray starts, so rays
/// starting inside the tube find their exit) bisected down to adjacent f64 values.
pub(super) fn torus_reference(case: &Case, centre: [f64; 3]) -> Option<f64> {
    let (enter, exit) = dd_sphere(case, centre, RADIUS + TUBE)?;
    let (enter, exit) = (enter.to_f64().max(0.0), exit.to_f64());
    if exit <= enter {
        return None;
    }
    let oc = dd::sub(dd::vec(case.origin), dd::vec(centre));
    let d = dd::vec(case.dir);
    let inside = |t: f64| torus_function(oc, d, t).is_negative();
    let start = inside(enter);
    const SAMPLES: usize = 4000;
    let step = (exit - enter) / SAMPLES as f64;
    let mut lo = enter;
    for i in 1..=SAMPLES {
        let hi = if i == SAMPLES {
            exit
        } else {
            enter + step * i as f64
        };
        if inside(hi) != start {
            let mut hi = hi;
            loop {
                let mid = 0.5 * (lo + hi);
                if mid <= lo || mid >= hi {
                    return Some(hi);
                }
                if inside(mid) == start {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
        }
        lo = hi;
    }
    None
}

/// Runs one variant over `cases`: its answers and its time per ray.
fn measure<F: Fn(&Case) -> Option<f64>>(
    timer: &Timer,
    cases: &[Case],
    crossing: F,
) -> (Vec<Option<f64>>, f64) {
    let answers: Vec<Option<f64>> = cases.iter().map(&crossing).collect();
    let ns = timer.ns_per_op(cases.len(), || {
        cases
            .iter()
            .map(|c| crossing(c).unwrap_or(0.0))
            .sum::<f64>()
    });
    (answers, ns)
}

/// A sphere or torus leaf centred on `centre`.
fn leaf<T: Real>(code: TypeCode, params: [f64; 6], centre: [f64; 3]) -> Leaf<T> {
    Leaf {
        code,
        params: params.map(T::from_f64),
        planes: 0..0,
        frame: Frame::from_transform(&Transform64::translation(centre)),
        complement: false,
    }
}

/// Rows for one primitive: f32 and f64, strategy on and off, at every distance (one
/// component per distance: the distances are different workloads).
fn primitive_rows(
    settings: Settings,
    components: [&'static str; 3],
    reference: &'static str,
    code: TypeCode,
    params: [f64; 6],
    distances: &[f64],
    answer: impl Fn(&Case, [f64; 3]) -> Option<f64>,
) -> Vec<Row> {
    let timer = Timer::new(settings);
    let count = settings.size(4000, 300);
    let mut rows = Vec::new();
    for (di, &distance) in distances.iter().enumerate() {
        let component = components[di];
        let centre = centre_at(distance);
        let mut rng = Rng::new(7, di as u32, code as u32);
        let cases: Vec<Case> = (0..count)
            .map(|_| {
                // Aim at the sphere's body or at the torus's tube.
                let aim = if code == TypeCode::Torus {
                    let phi = std::f64::consts::TAU * rng.next_f64();
                    let p = in_ball(&mut rng, 0.6 * TUBE);
                    [RADIUS * phi.cos() + p[0], RADIUS * phi.sin() + p[1], p[2]]
                } else {
                    in_ball(&mut rng, 0.8 * RADIUS)
                };
                aimed(&mut rng, std::array::from_fn(|k| centre[k] + aim[k]))
            })
            .collect();
        let want: Vec<Option<f64>> = cases.iter().map(|c| answer(c, centre)).collect();
        let leaf32 = leaf::<f32>(code, params, centre);
        let leaf64 = leaf::<f64>(code, params, centre);
        for strategy in [true, false] {
            let on_off = if strategy { "on" } else { "off" };
            let runs = [
                (
                    "f32",
                    measure(&timer, &cases, |c| leaf_crossing(&leaf32, c, strategy)),
                ),
                (
                    "f64",
                    measure(&timer, &cases, |c| leaf_crossing(&leaf64, c, strategy)),
                ),
            ];
            for (precision, (got, ns)) in runs {
                rows.push(Row {
                    component,
                    variant: format!("{precision}, strategy {on_off}"),
                    metric: METRIC,
                    reference,
                    error: max_error(&got, &want),
                    ns_per_op: ns,
                    memory_bytes: None,
                });
            }
        }
    }
    rows
}

/// Union of spheres as one list node or as a balanced binary tree, f32 and f64.
fn tree_rows(settings: Settings) -> crate::Result<Vec<Row>> {
    const PARTS: usize = 24;
    const PART_RADIUS: f64 = 15.0;
    let mut rng = Rng::new(11, 0, 0);
    let centres: Vec<[f64; 3]> = (0..PARTS)
        .map(|_| round32(in_ball(&mut rng, 60.0).map(|c| c + 500.0)))
        .collect();
    let shape = centres
        .iter()
        .map(|c| sphere(PART_RADIUS).map(|s| s.translate(c[0], c[1], c[2])))
        .reduce(|a, b| Ok(a? + b?))
        .expect("parts")?;
    let cases: Vec<Case> = (0..settings.size(4000, 300))
        .map(|_| {
            let c = centres[(rng.next_u32() as usize) % PARTS];
            let p = in_ball(&mut rng, 0.8 * PART_RADIUS);
            aimed(&mut rng, std::array::from_fn(|k| c[k] + p[k]))
        })
        .collect();
    let want: Vec<Option<f64>> = cases
        .iter()
        .map(|case| {
            centres
                .iter()
                .filter_map(|&c| sphere_reference(case, c, PART_RADIUS))
                .reduce(f64::min)
        })
        .collect();
    let timer = Timer::new(settings);
    let mut rows = Vec::new();
    for lists in [true, false] {
        let options = TreeOptions { lists };
        let form = if lists { "list node" } else { "binary tree" };
        let memory = tree_bytes(&shape, options)?;
        let p32 = PrimTree::<f32>::from_shape_with(&shape, options)?;
        let p64 = PrimTree::<f64>::from_shape_with(&shape, options)?;
        let hit = |step: hytrace_csg::kernel::Step<f64>| step.is_hit().then_some(step.t);
        let (got, ns) = measure(&timer, &cases, |c| {
            let s = p32.first_crossing(&c.ray(), 0.0);
            s.is_hit().then_some(f64::from(s.t))
        });
        rows.push(tree_row(form, "f32", &got, &want, ns, memory));
        let (got, ns) = measure(&timer, &cases, |c| hit(p64.first_crossing(&c.ray(), 0.0)));
        rows.push(tree_row(form, "f64", &got, &want, ns, memory));
    }
    Ok(rows)
}

/// Bytes of the Foundry tree a shape becomes (nodes and list members).
fn tree_bytes(shape: &Shape, options: TreeOptions) -> crate::Result<u64> {
    let tree = to_tree_with(shape, options)?;
    Ok(((tree.nodes.len() + tree.members.len()) * std::mem::size_of::<Node>()) as u64)
}

fn tree_row(
    form: &str,
    precision: &str,
    got: &[Option<f64>],
    want: &[Option<f64>],
    ns: f64,
    memory: u64,
) -> Row {
    Row {
        component: "csg tree form",
        variant: format!("{precision}, union of 24 spheres as a {form}"),
        metric: METRIC,
        reference: "double-double nearest sphere entry",
        error: max_error(got, want),
        ns_per_op: ns,
        memory_bytes: Some(memory),
    }
}

/// Every CSG row.
pub(super) fn rows(settings: Settings) -> crate::Result<Vec<Row>> {
    let mut rows = primitive_rows(
        settings,
        [
            "csg sphere, rays from 1 m",
            "csg sphere, rays from 20 m",
            "csg sphere, rays from 1 km",
        ],
        "double-double quadratic roots",
        TypeCode::Sphere,
        [0.0, 0.0, 0.0, RADIUS, 0.0, 0.0],
        &DISTANCES,
        |c, centre| sphere_reference(c, centre, RADIUS),
    );
    rows.extend(primitive_rows(
        settings,
        [
            "csg torus, rays from 1 m",
            "csg torus, rays from 20 m",
            "csg torus, rays from 1 km",
        ],
        "double-double torus function, bisected",
        TypeCode::Torus,
        [0.0, TUBE, RADIUS, 0.0, 0.0, 0.0],
        &DISTANCES[..2],
        torus_reference,
    ));
    rows.extend(tree_rows(settings)?);
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_agree_with_f64_on_easy_rays() {
        let case = Case {
            origin: [0.0, 0.0, -1000.0],
            dir: [0.0, 0.0, 1.0],
        };
        let t = sphere_reference(&case, [0.0; 3], RADIUS).unwrap();
        assert_eq!(t, 900.0);
        // Along the axis x = R: the tube is met at z = -r.
        let case = Case {
            origin: [RADIUS, 0.0, -1000.0],
            dir: [0.0, 0.0, 1.0],
        };
        let t = torus_reference(&case, [0.0; 3]).unwrap();
        assert!((t - (1000.0 - TUBE)).abs() < 1e-9, "{t}");
        // Through the hole: no crossing.
        let case = Case {
            origin: [0.0, 0.0, -1000.0],
            dir: [0.0, 0.0, 1.0],
        };
        assert_eq!(torus_reference(&case, [0.0; 3]), None);
    }
}
