//! The BVH searches against brute-force linear loops over the same instances: identical
//! hits (parameter and instance), ties and awkward rays included.

use super::*;
use hytrace_csg::{box3, sphere, to_tree, Shape};
use hytrace_foundry::Transform64;
use hytrace_volume::Rng;

/// A solid of one CSG prim.
fn add_solid(f: &mut Foundry, name: &str, shape: Shape) -> u32 {
    let mut s = f.begin_solid(name);
    s.add_csg(to_tree(&shape).unwrap(), 0, UNSET).unwrap();
    s.finish(0).unwrap()
}

/// Uniform in `[lo, hi)`.
fn uniform(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.next_f64()
}

/// Many small boxes and spheres around `centre` in a cube of half side 100: touching
/// boxes on a grid (shared faces), and random overlapping boxes (some rotated) and
/// spheres. With `mother`, the first instance is a big box and all others its daughters.
fn random_scene(seed: u32, centre: [f64; 3], mother: bool) -> Foundry {
    let mut f = Foundry::new();
    let world = add_solid(&mut f, "world", box3(400.0, 400.0, 400.0).unwrap());
    let cube = add_solid(&mut f, "cube", box3(10.0, 10.0, 10.0).unwrap());
    let slab = add_solid(&mut f, "slab", box3(14.0, 3.0, 7.0).unwrap());
    let ball = add_solid(&mut f, "ball", sphere(4.0).unwrap());
    let at = |p: [f64; 3]| Transform64::translation([0, 1, 2].map(|k| centre[k] + p[k]));
    if mother {
        f.add_instance(world, at([0.0; 3]), 0, 0).unwrap();
    }
    // Touching cubes: faces shared exactly (coordinates are multiples of 10).
    for i in 0..6 {
        for j in 0..6 {
            let p = [10.0 * i as f64 - 30.0, 10.0 * j as f64 - 30.0, -60.0];
            f.add_instance(cube, at(p), 0, 0).unwrap();
        }
    }
    let mut rng = Rng::new(seed, 0, 0);
    for n in 0..600 {
        let p = [0; 3].map(|_| uniform(&mut rng, -100.0, 100.0));
        let (solid, transform) = match n % 3 {
            0 => (cube, at(p)),
            1 => {
                let axis = [0; 3].map(|_| uniform(&mut rng, -1.0, 1.0));
                let rot = Transform64::rotation(axis, uniform(&mut rng, 0.0, 6.0));
                (slab, at(p).compose(&rot))
            }
            _ => (ball, at(p)),
        };
        f.add_instance(solid, transform, 0, 0).unwrap();
    }
    // Duplicates: same solid, same place (exactly tied crossings).
    for _ in 0..20 {
        let p = [0; 3].map(|_| (uniform(&mut rng, -9.0, 9.0) * 10.0).round());
        f.add_instance(cube, at(p), 0, 0).unwrap();
        f.add_instance(cube, at(p), 0, 0).unwrap();
    }
    if mother {
        for m in &mut f.inst_mother[1..] {
            m.index = 0;
        }
    }
    f.validate().unwrap();
    f
}

/// Random rays about `centre`: random and axis-aligned directions (zero components),
/// origins inside instances, on the shared grid faces and outside everything.
fn random_rays<T: Real>(seed: u32, centre: [f64; 3], count: usize) -> Vec<Ray<T>> {
    let mut rng = Rng::new(seed, 1, 0);
    (0..count)
        .map(|n| {
            let mut o = [0; 3].map(|_| uniform(&mut rng, -130.0, 130.0));
            if n.is_multiple_of(5) {
                // On the grid of touching cubes, at a shared face or edge.
                o = [0; 3].map(|_| uniform(&mut rng, -4.0, 4.0).round() * 10.0 - 5.0);
                o[2] = -60.0 + 5.0 * uniform(&mut rng, -1.0, 1.0).round();
            } else if n % 5 == 1 {
                // Inside the grid of touching cubes.
                o = [-35.0, -35.0, -65.0].map(|lo| lo + uniform(&mut rng, 0.0, 10.0));
                o[0] += 10.0 * (n % 6) as f64;
                o[1] += 10.0 * (n / 6 % 6) as f64;
            }
            let mut d = [0; 3].map(|_| uniform(&mut rng, -1.0, 1.0));
            match n % 4 {
                0 => d = [0.0; 3].map(|_| 0.0),
                1 => d[(n / 4) % 3] = 0.0,
                _ => {}
            }
            if d == [0.0; 3] {
                let mut axis = [0.0; 3];
                axis[(n / 4) % 3] = if n % 8 < 4 { 1.0 } else { -1.0 };
                d = axis;
            }
            let l = d.iter().map(|c| c * c).sum::<f64>().sqrt();
            Ray::from_f64([0, 1, 2].map(|k| centre[k] + o[k]), d.map(|c| c / l))
        })
        .collect()
}

/// The flat scene's answer by the linear loop over all instances.
fn linear_flat<T: Real>(s: &CpuScene<T>, ray: &Ray<T>, tmin: T, tmax: T) -> Option<Hit<T>> {
    let slabs = SlabRay::new(ray);
    (0..s.placements.len()).fold(None, |best, i| {
        let limit = best.map_or(tmax, |b| b.t);
        s.cross_instance(i, ray, Some(&slabs), tmin, limit).or(best)
    })
}

/// The navigator's answer by linear loops over roots and daughters.
fn linear_navigate<T: Real>(s: &CpuScene<T>, ray: &Ray<T>, tmin: T, tmax: T) -> Option<Hit<T>> {
    let Layout::Tree(h) = &s.layout else {
        panic!("not a hierarchy")
    };
    let mut current = None;
    let mut members = &h.roots.members;
    'descend: loop {
        for &c in members.iter().rev() {
            if s.contains(c, ray.origin) {
                current = Some(c);
                members = &h.daughters[c as usize].members;
                continue 'descend;
            }
        }
        break;
    }
    let exit = current.and_then(|c| s.exit(c as usize, ray, tmin, tmax));
    let slabs = SlabRay::new(ray);
    members.iter().fold(exit, |best, &d| {
        let limit = best.map_or(tmax, |b| b.t);
        s.cross_instance(d as usize, ray, Some(&slabs), tmin, limit)
            .or(best)
    })
}

fn key<T: Real>(h: Option<Hit<T>>) -> Option<(f64, u32)> {
    h.map(|h| (h.t.to_f64(), h.instance))
}

fn compare<T: Real>(mother: bool) {
    for (seed, centre) in [(1, [0.0; 3]), (2, [1e6, -1e6, 1e6]), (3, [-1e6, 0.0, 2e5])] {
        let f = random_scene(seed, centre, mother);
        let scene = CpuScene::<T>::new(&f).unwrap();
        let group = match &scene.layout {
            Layout::Flat(g) => g,
            Layout::Tree(h) => &h.daughters[0],
        };
        assert!(group.bvh.is_some(), "the group must be searched by BVH");
        let (mut hits, mut inside) = (0, 0);
        for ray in random_rays::<T>(seed, centre, 4000) {
            for (tmin, tmax) in [(T::ZERO, T::INFINITY), (T::ZERO, T::from_f64(20.0))] {
                let expected = if mother {
                    linear_navigate(&scene, &ray, tmin, tmax)
                } else {
                    linear_flat(&scene, &ray, tmin, tmax)
                };
                let got = scene.trace(&ray, tmin, tmax);
                assert_eq!(
                    key(got),
                    key(expected),
                    "seed {seed} ray {ray:?} tmin {tmin:?} tmax {tmax:?}"
                );
                assert_eq!(
                    scene.occluded(&ray, tmin, tmax),
                    expected.is_some(),
                    "any-hit, seed {seed} ray {ray:?} tmin {tmin:?} tmax {tmax:?}"
                );
                hits += usize::from(got.is_some());
            }
            let mut scratch = Vec::new();
            let located = scene.locate(group, ray.origin, &mut scratch);
            let linear = group
                .members
                .iter()
                .rev()
                .copied()
                .find(|&c| scene.contains(c, ray.origin));
            assert_eq!(located, linear, "seed {seed} origin {:?}", ray.origin);
            inside += usize::from(linear.is_some());
        }
        // The rays exercise both hits and misses, origins inside and outside.
        assert!(hits > 2000 && hits < 7900, "hits {hits}");
        assert!(inside > 700 && inside < 3900, "inside {inside}");
    }
}

#[test]
fn flat_bvh_matches_linear_f64() {
    compare::<f64>(false);
}

#[test]
fn flat_bvh_matches_linear_f32() {
    compare::<f32>(false);
}

#[test]
fn navigator_bvh_matches_linear_f64() {
    compare::<f64>(true);
}

#[test]
fn navigator_bvh_matches_linear_f32() {
    compare::<f32>(true);
}

/// One solid of many CSG prims (searched through the solid's own BVH) against the same
/// prims as separate one-prim solids placed where they are (searched by the instance BVH):
/// the same crossings, bit for bit, the prim index standing for the instance index.
fn many_prims_in_one_solid<T: Real>() {
    let (mut together, mut apart) = (Foundry::new(), Foundry::new());
    let mut rng = Rng::new(7, 0, 0);
    let mut b = together.begin_solid("cluster");
    for n in 0..40 {
        let p = [0; 3].map(|_| uniform(&mut rng, -80.0, 80.0));
        let shape = match n % 2 {
            0 => box3(30.0, 30.0, 30.0).unwrap(),
            _ => sphere(20.0).unwrap(),
        }
        .translate(p[0], p[1], p[2]);
        b.add_csg(to_tree(&shape).unwrap(), n, UNSET).unwrap();
        let single = add_solid(&mut apart, "one", shape);
        apart
            .add_instance(single, Transform64::IDENTITY, 0, 0)
            .unwrap();
    }
    let cluster = b.finish(0).unwrap();
    together
        .add_instance(cluster, Transform64::IDENTITY, 0, 0)
        .unwrap();
    let (together, apart) = (
        CpuScene::<T>::new(&together).unwrap(),
        CpuScene::<T>::new(&apart).unwrap(),
    );
    assert!(together.solids[0].prims.len() == 40 && together.placements.len() == 1);
    let mut hits = 0;
    for ray in random_rays::<T>(8, [0.0; 3], 4000) {
        let (a, b) = (
            together.trace(&ray, T::ZERO, T::INFINITY),
            apart.trace(&ray, T::ZERO, T::INFINITY),
        );
        assert_eq!(
            a.map(|h| (h.t.to_f64(), h.normal.to_f64(), h.prim)),
            b.map(|h| (h.t.to_f64(), h.normal.to_f64(), h.instance)),
            "ray {ray:?}"
        );
        hits += usize::from(a.is_some());
    }
    assert!(hits > 1000, "hits {hits}");
}

#[test]
fn solid_bvh_over_prims_matches_instances_f64() {
    many_prims_in_one_solid::<f64>();
}

#[test]
fn solid_bvh_over_prims_matches_instances_f32() {
    many_prims_in_one_solid::<f32>();
}

#[test]
fn f32_boxes_round_outward() {
    for v in [0.1, -0.1, 1e6 + 1e-3, -3.3e7, 1.0, 0.0, 16_777_217.0] {
        assert!(f64::from(bvh::f32_down(v)) <= v && f64::from(bvh::f32_up(v)) >= v);
    }
}
