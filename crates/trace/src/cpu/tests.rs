//! The BVH searches against brute-force linear loops over the same instances: identical
//! hits (parameter and instance), ties and awkward rays included.

use super::batch;
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
    let world = mother.then_some(world);
    place_layout(
        f,
        (seed, 0),
        centre,
        world,
        cube,
        600,
        |n, rng, at| match n % 3 {
            0 => (cube, at),
            1 => {
                let axis = [0; 3].map(|_| uniform(rng, -1.0, 1.0));
                let rot = Transform64::rotation(axis, uniform(rng, 0.0, 6.0));
                (slab, at.compose(&rot))
            }
            _ => (ball, at),
        },
    )
}

/// Places the test scenes' instances about `centre`, in a cube of half side 100: `world`
/// first when given (every other instance becomes its daughter), touching `cube`s on a
/// 6 x 6 grid (faces shared exactly: coordinates are multiples of 10), `count` solids at
/// random points as `pick(n, rng, translation)` chooses, then 20 pairs of `cube`s, each
/// pair at the same place (exactly tied crossings). Random numbers come from
/// `Rng::new(seed, stream, 0)` for `(seed, stream)` = `random`.
fn place_layout(
    mut f: Foundry,
    random: (u32, u32),
    centre: [f64; 3],
    world: Option<u32>,
    cube: u32,
    count: usize,
    mut pick: impl FnMut(usize, &mut Rng, Transform64) -> (u32, Transform64),
) -> Foundry {
    let at = |p: [f64; 3]| Transform64::translation([0, 1, 2].map(|k| centre[k] + p[k]));
    if let Some(world) = world {
        f.add_instance(world, at([0.0; 3]), 0, 0).unwrap();
    }
    for i in 0..6 {
        for j in 0..6 {
            let p = [10.0 * i as f64 - 30.0, 10.0 * j as f64 - 30.0, -60.0];
            f.add_instance(cube, at(p), 0, 0).unwrap();
        }
    }
    let mut rng = Rng::new(random.0, random.1, 0);
    for n in 0..count {
        let p = [0; 3].map(|_| uniform(&mut rng, -100.0, 100.0));
        let (solid, transform) = pick(n, &mut rng, at(p));
        f.add_instance(solid, transform, 0, 0).unwrap();
    }
    for _ in 0..20 {
        let p = [0; 3].map(|_| (uniform(&mut rng, -9.0, 9.0) * 10.0).round());
        f.add_instance(cube, at(p), 0, 0).unwrap();
        f.add_instance(cube, at(p), 0, 0).unwrap();
    }
    if world.is_some() {
        for m in &mut f.inst_mother[1..] {
            m.index = 0;
        }
    }
    f.validate().unwrap();
    f
}

/// Random rays about `centre`: random and axis-aligned directions (zero components),
/// origins inside instances, on the shared grid faces and outside everything.
fn random_rays(seed: u32, centre: [f64; 3], count: usize) -> Vec<Ray<f64>> {
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

/// `rows` rows of 64 camera rays (directions 1/4096 apart in a row) from 300 below and 100
/// above `centre`, looking at it: neighbouring rays close enough for the mesh searches to
/// take them as packets (8 in a row).
fn camera_rays(centre: [f64; 3], rows: usize) -> Vec<Ray<f64>> {
    let eye = [centre[0], centre[1] - 300.0, centre[2] + 100.0];
    (0..rows * 64)
        .map(|n| {
            let (u, v) = ((n % 64) as f64 / 4096.0, (n / 64) as f64 / rows as f64);
            let d = [u - 1.0 / 128.0, 1.0, -1.0 / 3.0 + 0.3 * (v - 0.5)];
            Ray::from_f64(eye, d)
        })
        .collect()
}

/// The flat scene's answer by the linear loop over all instances.
fn linear_flat<T: Real>(s: &CpuScene<T>, ray: &Ray<f64>, tmin: T, tmax: T) -> Option<Hit<T>> {
    let ray = &WorldRay::new(ray);
    let slabs = SlabRay::new(&ray.rounded);
    (0..s.placements.len()).fold(None, |best, i| {
        let limit = best.map_or(tmax, |b| b.t);
        s.cross_instance(i, ray, Some(&slabs), tmin, limit, &mut Direct)
            .or(best)
    })
}

/// The navigator's answer by linear loops over roots and daughters.
fn linear_navigate<T: Real>(s: &CpuScene<T>, ray: &Ray<f64>, tmin: T, tmax: T) -> Option<Hit<T>> {
    let ray = &WorldRay::new(ray);
    let Layout::Tree(h) = &s.layout else {
        panic!("not a hierarchy")
    };
    let mut current = None;
    let mut members = &h.roots.members;
    'descend: loop {
        for &c in members.iter().rev() {
            if s.contains(c, &ray.origin) {
                current = Some(c);
                members = &h.daughters[c as usize].members;
                continue 'descend;
            }
        }
        break;
    }
    let exit = current.and_then(|c| s.exit(c as usize, ray, tmin, tmax, &mut Direct));
    let slabs = SlabRay::new(&ray.rounded);
    members.iter().fold(exit, |best, &d| {
        let limit = best.map_or(tmax, |b| b.t);
        s.cross_instance(d as usize, ray, Some(&slabs), tmin, limit, &mut Direct)
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
        for ray in random_rays(seed, centre, 4000) {
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
            let origin = WorldPoint::new(ray.origin);
            let located = scene.locate(group, &origin, &mut scratch);
            let linear = group
                .members
                .iter()
                .rev()
                .copied()
                .find(|&c| scene.contains(c, &origin));
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
/// the same crossings, the prim index standing for the instance index. Each solid is
/// solved on the ray rebased to its own centre, so parameters agree up to rounding at the
/// solids' scale (200 mm), and a tie within that may go to either prim.
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
    let (mut hits, mut ties) = (0, 0);
    for ray in random_rays(8, [0.0; 3], 4000) {
        let (a, b) = (
            together.trace(&ray, T::ZERO, T::INFINITY),
            apart.trace(&ray, T::ZERO, T::INFINITY),
        );
        let close = match (a, b) {
            (None, None) => true,
            (Some(a), Some(b)) => {
                let tol = 16.0 * T::EPSILON.to_f64() * 200.0;
                let same_t = (a.t.to_f64() - b.t.to_f64()).abs() <= tol;
                let normal = a.normal.dot(b.normal).to_f64() > 1.0 - 1e-3;
                same_t && (normal || a.prim != b.instance)
            }
            _ => false,
        };
        assert!(close, "ray {ray:?}: solid {a:?}, instances {b:?}");
        ties += usize::from(a.zip(b).is_some_and(|(a, b)| a.prim != b.instance));
        hits += usize::from(a.is_some());
    }
    assert!(hits > 1000, "hits {hits}");
    assert!(ties * 1000 <= hits, "{ties} ties of {hits} hits");
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

/// A triangle, f64 vertices.
type Tri = [[f64; 3]; 3];

/// A mesh prim of `tris` (f64 vertices) offset by `at`.
fn add_mesh_prim(s: &mut hytrace_foundry::SolidBuilder<'_>, tris: &[Tri], at: [f64; 3]) {
    let triangles: Vec<hytrace_foundry::Triangle> = tris
        .iter()
        .map(|t| hytrace_foundry::Triangle {
            v: t.map(|v| {
                [
                    (v[0] + at[0]) as f32,
                    (v[1] + at[1]) as f32,
                    (v[2] + at[2]) as f32,
                    0.0,
                ]
            }),
        })
        .collect();
    s.add_mesh(&triangles, None, 0, UNSET).unwrap();
}

/// The triangles of an icosphere of radius `r` and of an axis-aligned cube of half side `h`,
/// both closed and outward wound.
fn ball_and_cube(r: f64, h: f64) -> (Vec<Tri>, Vec<Tri>) {
    let (verts, faces) = hytrace_csg::tessellate::icosphere(2);
    let ball = faces
        .iter()
        .map(|f| f.map(|i| verts[i].map(|c| r * c)))
        .collect();
    let square = |z: f64| vec![[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]];
    let cube =
        hytrace_csg::tessellate::section_stack(&[square(-h), square(h)], &[0, 1, 2, 3]).unwrap();
    (ball, cube)
}

/// Mesh solids placed many times about `centre` ([`place_layout`]): balls, cubes (touching
/// on the grid, and tied pairs), CSG boxes among them, and a solid of twelve prims (meshes and CSG, searched through the solid's BVH). With `mother`, the first
/// instance is a big mesh cube and all others its daughters, so locating an origin and
/// leaving the located volume ask mesh prims too.
fn mesh_instances(seed: u32, centre: [f64; 3], mother: bool) -> Foundry {
    let (ball, cube) = ball_and_cube(6.0, 5.0);
    let (_, world_cube) = ball_and_cube(1.0, 400.0);
    let mut f = Foundry::new();
    let mesh_solid = |f: &mut Foundry, name: &str, tris: &[Tri]| {
        let mut s = f.begin_solid(name);
        add_mesh_prim(&mut s, tris, [0.0; 3]);
        s.finish(0).unwrap()
    };
    let world = mesh_solid(&mut f, "world", &world_cube);
    let ball_id = mesh_solid(&mut f, "ball", &ball);
    let cube_id = mesh_solid(&mut f, "cube", &cube);
    let csg_box = add_solid(&mut f, "box", box3(8.0, 3.0, 6.0).unwrap());
    let cluster = {
        let mut s = f.begin_solid("cluster");
        for k in 0..12 {
            let at = [(k % 4) as f64 * 9.0 - 13.5, (k / 4) as f64 * 9.0 - 9.0, 0.0];
            if k % 3 == 0 {
                let tree = to_tree(&sphere(4.0).unwrap().translate(at[0], at[1], at[2])).unwrap();
                s.add_csg(tree, 0, UNSET).unwrap();
            } else {
                add_mesh_prim(&mut s, if k % 2 == 0 { &ball } else { &cube }, at);
            }
        }
        s.finish(0).unwrap()
    };
    let world = mother.then_some(world);
    place_layout(f, (seed, 2), centre, world, cube_id, 300, |n, rng, at| {
        let axis = [0; 3].map(|_| uniform(rng, -1.0, 1.0));
        let turned = at.compose(&Transform64::rotation(axis, uniform(rng, 0.0, 6.0)));
        let solid = [ball_id, ball_id, cube_id, csg_box, cluster][n % 5];
        (solid, turned)
    })
}

/// A hit's bits: distance, normal, instance and prim.
type HitBits = Option<(u64, [u64; 3], u32, u32)>;

fn hit_bits<T: Real>(h: &Option<Hit<T>>) -> HitBits {
    h.map(|h| {
        (
            h.t.to_f64().to_bits(),
            h.normal.to_f64().map(f64::to_bits),
            h.instance,
            h.prim,
        )
    })
}

/// Asserts that `trace_batch` answers `rays` as `want` (their `trace`s) bit for bit, in
/// batches of several sizes, interleaving the searches of meshes of at least `min_bytes`.
fn assert_batches_answer<T: Real>(
    scene: &CpuScene<T>,
    rays: &[(Ray<f64>, T, T)],
    want: &[Option<Hit<T>>],
    min_bytes: usize,
) {
    let mut out = Vec::new();
    let mut scratch = TraceScratch::interleaving_from(min_bytes);
    for size in [1, 3, 8, 13, BATCH] {
        for (chunk, want) in rays.chunks(size).zip(want.chunks(size)) {
            scene.trace_batch(chunk, &mut scratch, &mut out);
            assert_eq!(out.len(), chunk.len());
            for ((ray, got), want) in chunk.iter().zip(&out).zip(want) {
                assert_eq!(
                    hit_bits(got),
                    hit_bits(want),
                    "{} batches of {size}, interleaving from {min_bytes} bytes, ray {ray:?}",
                    T::NAME
                );
            }
        }
    }
}

/// `rays` with three `(tmin, tmax)` windows in turn: the whole ray, a short one, a late
/// start.
fn windowed<T: Real>(rays: Vec<Ray<f64>>) -> Vec<(Ray<f64>, T, T)> {
    rays.into_iter()
        .enumerate()
        .map(|(n, r)| match n % 3 {
            0 => (r, T::ZERO, T::INFINITY),
            1 => (r, T::ZERO, T::from_f64(25.0)),
            _ => (r, T::from_f64(7.0), T::INFINITY),
        })
        .collect()
}

/// `trace_batch` answers every ray bit for bit as `trace` does, on scenes whose rays meet
/// from none to dozens of mesh prims, flat and navigated, near and far from the origin,
/// in batches of every size.
fn batch_case<T: Real>(mother: bool) {
    let mut by_queries = [0usize; 3];
    for (seed, centre) in [(1, [0.0; 3]), (2, [2.0e4, -1.0e4, 5.0e3])] {
        let scene = CpuScene::<T>::new(&mesh_instances(seed, centre, mother)).unwrap();
        assert!(scene.lone_mesh().is_none());
        let rays = windowed(random_rays(seed, centre, 3000));
        let want: Vec<Option<Hit<T>>> = rays
            .iter()
            .map(|(r, a, b)| scene.trace(r, *a, *b))
            .collect();
        for (ray, tmin, tmax) in &rays {
            by_queries[match scene.mesh_queries(ray, *tmin, *tmax) {
                0 => 0,
                n if n <= batch::REPLAYS => 1,
                _ => 2,
            }] += 1;
        }
        // Every mesh interleaved (these are small), and none (the default for them).
        for min_bytes in [0, INTERLEAVE_MIN_BYTES] {
            assert_batches_answer(&scene, &rays, &want, min_bytes);
        }
        let hits = want.iter().filter(|h| h.is_some()).count();
        assert!(hits > 1000 && hits < 2900, "{hits} of 3000 rays hit");
    }
    // Rays with no mesh query, with a few, and with more than the replays take.
    assert!(
        by_queries.iter().all(|&n| n > 100),
        "rays by mesh queries: {by_queries:?}"
    );
}

/// A scene of one placed mesh takes `trace_batch`'s lone-mesh path (no replays) when the
/// placement is axis-aligned, and the replayed traces when it is not; either way every
/// ray's answer is `trace`'s, bit for bit: near and far (2e4) from the origin, turned by a
/// right angle, with `tmin`/`tmax` windows, along the axes, and from the surface.
#[test]
fn lone_mesh_batches_answer_as_single_traces() {
    let (ball, cube) = ball_and_cube(60.0, 40.0);
    let cases = [
        (&ball, [0.0; 3], 0.0, true),
        (
            &cube,
            [2.0e4, -1.0e4, 5.0e3],
            std::f64::consts::FRAC_PI_2,
            true,
        ),
        (&ball, [-3.0e3, 0.0, 1.0e4], std::f64::consts::PI, true),
        (&cube, [0.0; 3], 0.6, false),
    ];
    for (seed, (tris, centre, turn, lone)) in cases.into_iter().enumerate() {
        let mut f = Foundry::new();
        let solid = {
            let mut s = f.begin_solid("mesh");
            add_mesh_prim(&mut s, tris, [0.0; 3]);
            s.finish(0).unwrap()
        };
        let place =
            Transform64::translation(centre).compose(&Transform64::rotation([0.0, 0.0, 1.0], turn));
        f.add_instance(solid, place, 0, 0).unwrap();
        let scene = CpuScene::<f32>::new(&f).unwrap();
        assert_eq!(scene.lone_mesh().is_some(), lone, "case {seed}");
        let mut rays = windowed(random_rays(seed as u32 + 10, centre, 3000));
        // Camera rays, searched as packets.
        rays.extend(windowed(camera_rays(centre, 40)));
        // From the surface: each hit's point, `tmin` its distance.
        let from_surface: Vec<_> = rays
            .iter()
            .filter_map(|(r, a, b)| scene.trace(r, *a, *b).map(|h| (*r, h.t, f32::INFINITY)))
            .collect();
        rays.extend(from_surface);
        let want: Vec<_> = rays
            .iter()
            .map(|(r, a, b)| scene.trace(r, *a, *b))
            .collect();
        let hits = want.iter().filter(|h| h.is_some()).count();
        assert!(hits > 500, "case {seed}: {hits} of {} rays hit", rays.len());
        assert_batches_answer(&scene, &rays, &want, 0);
    }
}

#[test]
fn batch_traces_answer_as_single_traces_flat_f32() {
    batch_case::<f32>(false);
}

#[test]
fn batch_traces_answer_as_single_traces_navigated_f32() {
    batch_case::<f32>(true);
}

#[test]
fn batch_traces_answer_as_single_traces_f64() {
    batch_case::<f64>(false);
}
