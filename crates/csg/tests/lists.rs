//! N-ary list nodes against float64 interval arithmetic: unions of many overlapping,
//! touching or disjoint spheres and intersections of many spheres, walked crossing by
//! crossing from outside and from inside.

use hytrace_csg::{sphere, to_tree_with, PrimTree, Ray, Shape, TreeOptions};
use hytrace_foundry::TypeCode;

mod common;
use common::{Random, Rng};

/// The interval of a ray (unit direction) inside a sphere, if any.
fn sphere_span(c: [f64; 3], r: f64, o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
    let oc = [o[0] - c[0], o[1] - c[1], o[2] - c[2]];
    let b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
    let h = [oc[0] - b * d[0], oc[1] - b * d[1], oc[2] - b * d[2]];
    let q = r * r - (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
    (q > 0.0).then(|| (-b - q.sqrt(), -b + q.sqrt()))
}

/// Boundary points of a union (or intersection) of intervals, ascending.
fn boundaries(spans: &[(f64, f64)], union: bool) -> Vec<f64> {
    let mut events: Vec<(f64, i32)> = spans.iter().flat_map(|&(a, b)| [(a, 1), (b, -1)]).collect();
    events.sort_by(|x, y| x.partial_cmp(y).unwrap());
    let need = if union { 1 } else { spans.len() as i32 };
    let (mut count, mut out) = (0, Vec::new());
    for (t, delta) in events {
        let before = count >= need;
        count += delta;
        if before != (count >= need) {
            out.push(t);
        }
    }
    out
}

fn check(centres: &[[f64; 3]], radii: &[f64], union: bool, seed: u64) {
    check_with(centres, radii, union, seed, TreeOptions::default());
}

/// Compares every crossing with the intervals; with lists on, the tree must be one list
/// node, with lists off it must hold none.
fn check_with(centres: &[[f64; 3]], radii: &[f64], union: bool, seed: u64, options: TreeOptions) {
    let parts: Vec<Shape> = centres
        .iter()
        .zip(radii)
        .map(|(c, &r)| sphere(r).unwrap().translate(c[0], c[1], c[2]))
        .collect();
    let shape = parts
        .iter()
        .cloned()
        .reduce(|a, b| if union { a + b } else { a * b })
        .unwrap();
    let tree = to_tree_with(&shape, options).unwrap();
    let want = if union {
        TypeCode::ListContiguous
    } else {
        TypeCode::ListOverlap
    };
    if options.lists {
        assert_eq!(tree.nodes[0].typecode, want as u32, "one list node");
    } else {
        assert!(
            tree.nodes.iter().all(|n| n.typecode != want as u32),
            "no list node"
        );
        assert!(tree.members.is_empty());
    }
    let prim = PrimTree::<f64>::from_shape_with(&shape, options).unwrap();
    let mut rng = Rng(seed);
    for _ in 0..2000 {
        let (o, d) = rng.aimed(60.0, 20.0);
        let spans: Vec<(f64, f64)> = centres
            .iter()
            .zip(radii)
            .filter_map(|(c, &r)| sphere_span(*c, r, o, d))
            .collect();
        let reference: Vec<f64> = if !union && spans.len() < centres.len() {
            Vec::new()
        } else {
            boundaries(&spans, union)
                .into_iter()
                .filter(|&t| t > 1e-9)
                .collect()
        };
        let ray = Ray::from_f64(o, d);
        let mut tmin = 0.0;
        for (k, want) in reference.iter().enumerate() {
            let s = prim.first_crossing(&ray, tmin);
            assert!(
                (s.t - want).abs() < 1e-9,
                "crossing {k}: {} vs {want} ({o:?} {d:?})",
                s.t
            );
            tmin = s.t;
        }
        assert!(
            prim.first_crossing(&ray, tmin).t.is_infinite(),
            "extra crossing"
        );
    }
}

/// 24 spheres, overlapping and disjoint, in a 60 mm cube; radii exact in f32, as the
/// Foundry stores primitive parameters.
fn scattered_spheres(seed: u64) -> (Vec<[f64; 3]>, Vec<f64>) {
    let mut rng = Rng(seed);
    let centres: Vec<[f64; 3]> = (0..24)
        .map(|_| {
            [
                rng.range(-30., 30.),
                rng.range(-30., 30.),
                rng.range(-30., 30.),
            ]
        })
        .collect();
    let radii: Vec<f64> = (0..24).map(|_| rng.range(3., 12.) as f32 as f64).collect();
    (centres, radii)
}

#[test]
fn union_list_of_overlapping_and_disjoint_spheres_matches_intervals() {
    let (centres, radii) = scattered_spheres(1);
    check(&centres, &radii, true, 2);
}

#[test]
fn without_lists_a_union_is_a_binary_tree_with_the_same_crossings() {
    let (centres, radii) = scattered_spheres(6);
    check_with(&centres, &radii, true, 7, TreeOptions { lists: false });
}

#[test]
fn union_list_of_touching_spheres_has_no_internal_crossings() {
    // A row of spheres touching at single points: internal tangencies are not crossings.
    let centres: Vec<[f64; 3]> = (0..8)
        .map(|i| [-35.0 + 10.0 * i as f64, 0.0, 0.0])
        .collect();
    check(&centres, &[5.0; 8], true, 3);
}

#[test]
fn intersection_list_of_spheres_matches_intervals() {
    let mut rng = Rng(4);
    let centres: Vec<[f64; 3]> = (0..7)
        .map(|_| [rng.range(-8., 8.), rng.range(-8., 8.), rng.range(-8., 8.)])
        .collect();
    let radii: Vec<f64> = (0..7).map(|_| rng.range(25., 35.) as f32 as f64).collect();
    check(&centres, &radii, false, 5);
}
