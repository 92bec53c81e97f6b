//! Hierarchical DDA and transmittance estimators against independent references: analytic
//! integrals, a Gauss-Legendre quadrature of `sample_trilinear` between sorted cell-face
//! crossings (found without any walk), and direct lookups along the rays.

use hytrace_testkit::vec3::normalized as unit;
use hytrace_volume::{
    fog_sphere, global_range, sample_nearest, sample_stochastic, sample_trilinear, transmittance,
    transmittance_batch, CellWalk, Coord, DenseGrid, Estimate, Estimator, Filter, GridMap,
    IndexRay, IndexTransmittance, Majorant, RangeMips, Ray, Rng, Segment, SegmentWalk,
    TransmittanceParams, VoxelGrid, LEVEL_GLOBAL, LEVEL_OUTSIDE,
};

/// The next uniform number in [0, 1) of `state` (the crate's counter-based generator).
fn rng(state: &mut Rng) -> f64 {
    state.next_f64()
}

fn random_dir(state: &mut Rng) -> [f64; 3] {
    loop {
        let v: [f64; 3] = std::array::from_fn(|_| rng(state) * 2.0 - 1.0);
        let n2 = v.iter().map(|c| c * c).sum::<f64>();
        if n2 > 0.01 && n2 <= 1.0 {
            return unit(v);
        }
    }
}

/// Sparse random values in [lo, hi) (a fraction `fill` of the voxels), the rest background.
fn random_grid(
    state: &mut Rng,
    origin: [i32; 3],
    dims: [u32; 3],
    background: f32,
    fill: f64,
    (lo, hi): (f64, f64),
) -> DenseGrid {
    let mut g = DenseGrid::new(origin, dims, background).unwrap();
    for v in g.values.iter_mut() {
        if rng(state) < fill {
            *v = (lo + rng(state) * (hi - lo)) as f32;
        }
    }
    g
}

/// A sheared map with anisotropic voxels and an offset origin.
fn anisotropic_map() -> GridMap {
    GridMap::new(
        [[0.5, 0.05, 0.0], [0.0, 0.3, -0.02], [0.1, 0.0, 1.25]],
        [3.0, -40.0, 12.5],
    )
    .unwrap()
}

/// A world ray through index-space point `p` along index-space direction `d` (unit in
/// world space), starting `back` world units before `p`.
fn world_ray(map: &GridMap, p: [f64; 3], d: [f64; 3], back: f64, tmax: f64) -> Ray {
    let zero = map.index_to_world([0.0; 3]);
    let image = map.index_to_world(d);
    let dir = unit(std::array::from_fn(|k| image[k] - zero[k]));
    let at = map.index_to_world(p);
    let origin = std::array::from_fn(|k| at[k] - back * dir[k]);
    Ray::new(origin, dir, 0.0, tmax)
}

/// Integral of the lookup (trilinear, or nearest) along `ray` over `[t0, t1]` (finite): the
/// cell faces crossed are found by solving for every integer plane and sorting, and each
/// piece between them (a cubic, or a constant) gets 3-point Gauss-Legendre.
fn reference_integral<G: VoxelGrid>(g: &G, ray: &IndexRay, t0: f64, t1: f64, nearest: bool) -> f64 {
    let off = if nearest { 0.5 } else { 0.0 };
    let mut ts = vec![t0, t1];
    for k in 0..3 {
        let d = ray.dir[k];
        if d == 0.0 {
            continue;
        }
        let (a, b) = (ray.at(t0)[k], ray.at(t1)[k]);
        let (a, b) = (a.min(b), a.max(b));
        for j in (a - off).ceil() as i64..=(b - off).floor() as i64 {
            let t = (j as f64 + off - ray.origin[k]) / d;
            if t > t0 && t < t1 {
                ts.push(t);
            }
        }
    }
    ts.sort_by(f64::total_cmp);
    let x = (0.6f64).sqrt();
    let mut sum = 0.0;
    for w in ts.windows(2) {
        let (mid, half) = (0.5 * (w[0] + w[1]), 0.5 * (w[1] - w[0]));
        for (node, weight) in [(-x, 5.0 / 9.0), (0.0, 8.0 / 9.0), (x, 5.0 / 9.0)] {
            let p = ray.at(mid + half * node);
            let v = if nearest {
                sample_nearest(g, p) as f64
            } else {
                sample_trilinear(g, p)
            };
            sum += half * weight * v;
        }
    }
    sum
}

fn params(estimator: Estimator) -> TransmittanceParams {
    TransmittanceParams::new(estimator)
}

fn estimate<G: VoxelGrid>(g: &G, mips: &RangeMips, ray: &Ray, p: &TransmittanceParams) -> Estimate {
    transmittance(g, mips, ray, 0, p).unwrap()
}

fn assert_rel(a: f64, b: f64, tol: f64, what: &str) {
    assert!(
        (a - b).abs() <= tol * b.abs().max(1e-300),
        "{what}: {a} vs {b} (relative {:e})",
        (a - b).abs() / b.abs()
    );
}

/// Checks the walk's contract on one ray: segments sorted, contiguous, non-empty, covering
/// `[tmin, tmax]`; every lookup (trilinear, nearest, stochastic) at many `t` of a segment,
/// its ends included, within its range; fine segments naming the block the ray is in.
fn check_segments<G: VoxelGrid>(
    g: &G,
    mips: &RangeMips,
    ray: &IndexRay,
    segs: &[Segment],
    state: &mut Rng,
) {
    if ray.tmax <= ray.tmin {
        assert!(segs.is_empty(), "{segs:?}");
        return;
    }
    assert_eq!(segs[0].t0, ray.tmin, "{ray:?}");
    assert_eq!(segs.last().unwrap().t1, ray.tmax, "{ray:?}");
    for w in segs.windows(2) {
        assert_eq!(w[0].t1, w[1].t0, "{ray:?}");
    }
    for s in segs {
        assert!(s.t1 > s.t0, "{s:?}");
        let mut ts = vec![s.t0, 0.5 * (s.t0 + s.t1)];
        if s.t1.is_finite() {
            ts.push(s.t1);
            ts.extend((0..12).map(|_| s.t0 + rng(state) * (s.t1 - s.t0)));
        } else {
            ts.extend([1.0, 10.0, 1e3, 1e6].map(|d| s.t0 + d));
        }
        let slack = 1e-9 * (1.0 + s.range.max.abs().max(s.range.min.abs()) as f64);
        for t in ts {
            let p = ray.at(t);
            let u = [rng(state), rng(state), rng(state)];
            for v in [
                sample_trilinear(g, p),
                sample_nearest(g, p) as f64,
                sample_stochastic(g, p, u) as f64,
            ] {
                assert!(
                    v >= s.range.min as f64 - slack && v <= s.range.max as f64 + slack,
                    "lookup {v} at t {t} {p:?} outside {s:?} of {ray:?}"
                );
            }
        }
        // The block the walk names is the one holding the segment's middle, away from faces.
        if s.level < LEVEL_GLOBAL && s.t1 - s.t0 > 1e-6 {
            let side = mips.levels[s.level as usize].side as f64;
            let p = ray.at(0.5 * (s.t0 + s.t1));
            let near_face = (0..3).any(|k| {
                let q = (p[k] + 0.5) / side;
                ray.dir[k] != 0.0 && (q - q.round()).abs() * side < 1e-7
            });
            if !near_face {
                let block = p.map(|c| ((c + 0.5) / side).floor() as i32);
                assert_eq!(
                    mips.range(s.level as usize, block),
                    s.range,
                    "{s:?} at {p:?} of {ray:?}"
                );
            }
        }
    }
}

/// Checks the walks at every level and the global one.
fn check_all_walks<G: VoxelGrid>(g: &G, mips: &RangeMips, ray: &IndexRay, state: &mut Rng) {
    for level in 0..mips.levels.len() {
        let segs: Vec<Segment> = SegmentWalk::new(mips, ray, level).unwrap().collect();
        // Levels from the requested one to the coarsest; never the fallback range.
        assert!(segs.iter().all(|s| s.level == LEVEL_OUTSIDE
            || (s.level as usize >= level && (s.level as usize) < mips.levels.len())));
        check_segments(g, mips, ray, &segs, state);
    }
    let segs: Vec<Segment> = SegmentWalk::global(mips, ray, global_range(mips))
        .unwrap()
        .collect();
    check_segments(g, mips, ray, &segs, state);
}

fn test_grids(state: &mut Rng) -> Vec<DenseGrid> {
    let mut sparse = random_grid(state, [-37, 5, -70], [45, 29, 80], 0.0, 0.4, (-3.0, 7.0));
    // Far-apart clusters, so the coarse levels hold constant blocks between them.
    sparse.set([-37, 5, -70], 9.0);
    let mut blocks = DenseGrid::new([-70, -70, -70], [140, 140, 140], 0.0).unwrap();
    for (i, c) in [[-60, -60, -60], [0, 0, 0], [40, -20, 55], [7, 7, 8]]
        .iter()
        .enumerate()
    {
        for z in 0..6 {
            for y in 0..6 {
                for x in 0..6 {
                    blocks.set([c[0] + x, c[1] + y, c[2] + z], 1.0 + i as f32);
                }
            }
        }
    }
    vec![sparse, blocks, fog_sphere(20.0, 6.0).unwrap()]
}

#[test]
fn segments_bound_every_lookup_on_random_rays() {
    let mut state = Rng::new(1, 0, 0);
    for g in test_grids(&mut state) {
        let mips = RangeMips::build(&g).unwrap();
        let lo = g.origin.map(|c| c as f64 - 20.0);
        for i in 0..60 {
            let p: [f64; 3] =
                std::array::from_fn(|k| lo[k] + rng(&mut state) * (g.dims[k] as f64 + 40.0));
            let d = random_dir(&mut state);
            let tmin = -60.0 * rng(&mut state);
            let tmax = if i % 3 == 0 {
                f64::INFINITY
            } else {
                tmin + 200.0 * rng(&mut state)
            };
            let ray = IndexRay::new(p, d, tmin, tmax).unwrap();
            check_all_walks(&g, &mips, &ray, &mut state);
        }
    }
}

#[test]
fn zero_direction_components() {
    let mut state = Rng::new(2, 0, 0);
    for g in test_grids(&mut state) {
        let mips = RangeMips::build(&g).unwrap();
        for i in 0..60 {
            // One or two zero components; the others random or exactly on faces and centres.
            let zeros = if i % 2 == 0 { 1 } else { 2 };
            let first = i % 3;
            let mut d = random_dir(&mut state);
            for z in 0..zeros {
                d[(first + z) % 3] = 0.0;
            }
            if d.iter().all(|c| *c == 0.0) {
                d[(first + 2) % 3] = 1.0;
            }
            let d = unit(d);
            let p: [f64; 3] = std::array::from_fn(|k| {
                let c = g.origin[k] as f64 + rng(&mut state) * g.dims[k] as f64;
                match (i / 6) % 3 {
                    0 => c,
                    1 => (c / 8.0).round() * 8.0 - 0.5,
                    _ => c.round(),
                }
            });
            let tmax = if i % 5 == 0 { f64::INFINITY } else { 150.0 };
            let ray = IndexRay::new(p, d, -150.0, tmax).unwrap();
            check_all_walks(&g, &mips, &ray, &mut state);
        }
    }
    // Components too small to divide by safely: the plane parameters overflow to +-inf,
    // never to NaN.
    let g = &test_grids(&mut state)[0];
    let mips = RangeMips::build(g).unwrap();
    for tiny in [1e-300, 5e-324, -1e-310] {
        for p in [[2.25, 20.0, -100.0], [7.5, 15.5, -100.0]] {
            let ray = IndexRay::new(p, [tiny, -tiny, 1.0], -50.0, 300.0).unwrap();
            check_all_walks(g, &mips, &ray, &mut state);
        }
    }
    // Exact along an axis-aligned ray through the random grid, against the reference.
    let ray = Ray::new([2.25, 20.0, -100.0], [0.0, 0.0, 1.0], 0.0, 200.0);
    let index = IndexRay::from_world(&ray, g.map()).unwrap();
    let tau = reference_integral(g, &index, 0.0, 200.0, false);
    let e = estimate(g, &mips, &ray, &params(Estimator::Exact));
    assert_rel(e.transmittance, (-tau).exp(), 1e-9, "axis-aligned exact");
}

/// Two 8^3 blocks of value 1, 512 voxels apart along x: a sparse source other than
/// [`DenseGrid`].
struct TwoBlocks {
    map: GridMap,
}

impl VoxelGrid for TwoBlocks {
    fn background(&self) -> f32 {
        0.0
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        let inside = |o: i32| {
            ijk[0] >= o && ijk[0] < o + 8 && (0..8).contains(&ijk[1]) && (0..8).contains(&ijk[2])
        };
        (inside(0) || inside(512)) as u8 as f32
    }

    fn block_origins(&self) -> Result<Vec<Coord>, hytrace_volume::VolumeError> {
        Ok(vec![[0, 0, 0], [512, 0, 0]])
    }

    fn map(&self) -> &GridMap {
        &self.map
    }
}

#[test]
fn empty_space_is_skipped_at_coarse_levels() {
    let g = TwoBlocks {
        map: GridMap::IDENTITY,
    };
    let mips = RangeMips::build(&g).unwrap();
    let ray = IndexRay::new([-100.0, 3.3, 4.1], unit([1.0, 0.001, -0.002]), 0.0, 800.0).unwrap();
    let segs: Vec<Segment> = SegmentWalk::new(&mips, &ray, 0).unwrap().collect();
    let coarse = segs.iter().filter(|s| s.level == 3).count();
    assert!(coarse >= 5 && segs.len() < 30, "{segs:#?}");
    let mut state = Rng::new(18, 0, 0);
    check_all_walks(&g, &mips, &ray, &mut state);
    // Each block adds 8 along the ray, plus the halo's blend on either side (values ramp
    // from 0 to 1 over one voxel: half a voxel's worth each side).
    let world = Ray::new(ray.origin, ray.dir, 0.0, 800.0);
    let tau = reference_integral(&g, &ray, 0.0, 800.0, false);
    assert!((tau - 2.0 * 8.0 / ray.dir[0]).abs() < 0.5, "{tau}");
    let e = estimate(&g, &mips, &world, &params(Estimator::Exact));
    assert_rel(e.transmittance, (-tau).exp(), 1e-9, "two blocks");
}

#[test]
fn ray_along_brick_face() {
    let mut state = Rng::new(3, 0, 0);
    let g = random_grid(
        &mut state,
        [-20, -20, -20],
        [90, 90, 90],
        0.0,
        0.5,
        (0.0, 4.0),
    );
    let mips = RangeMips::build(&g).unwrap();
    // Faces of level 0 (7.5), of levels 0-1 (15.5), of every level (63.5, -0.5), and
    // their edges, along each axis and along a diagonal within the face.
    let faces = [7.5, 15.5, 63.5, -0.5, 39.5];
    let mut rays = Vec::new();
    for (a, b) in faces.iter().zip(faces.iter().rev()) {
        for axis in 0..3 {
            let mut p = [3.25, 11.0, 29.75];
            p[(axis + 1) % 3] = *a;
            let mut d = [0.0; 3];
            d[axis] = if axis == 1 { -1.0 } else { 1.0 };
            rays.push((p, d));
            p[(axis + 2) % 3] = *b;
            rays.push((p, d));
            let mut diag = [0.6, 0.8, 0.6];
            diag[(axis + 1) % 3] = 0.0;
            rays.push((p, unit(diag)));
        }
    }
    // Diagonals through block corners at every level.
    rays.push(([-0.5; 3], unit([1.0, 1.0, 1.0])));
    rays.push(([63.5, -0.5, 63.5], unit([-1.0, 1.0, -1.0])));
    for (p, d) in rays {
        for tmax in [60.0, f64::INFINITY] {
            let ray = IndexRay::new(p, d, -70.0, tmax).unwrap();
            check_all_walks(&g, &mips, &ray, &mut state);
        }
        let world = Ray::new(p, d, -70.0, 90.0);
        let index = IndexRay::from_world(&world, g.map()).unwrap();
        for (filter, nearest) in [(Filter::Trilinear, false), (Filter::Nearest, true)] {
            let tau = reference_integral(&g, &index, -70.0, 90.0, nearest);
            let mut p = params(Estimator::Exact);
            p.density_scale = 0.01;
            p.filter = filter;
            let e = estimate(&g, &mips, &world, &p);
            assert_rel(e.transmittance, (-0.01 * tau).exp(), 1e-9, "face exact");
        }
    }
}

#[test]
fn ray_starting_on_boundary() {
    let mut state = Rng::new(4, 0, 0);
    let g = random_grid(&mut state, [0, 0, 0], [30, 20, 25], 0.0, 0.6, (0.0, 2.0));
    let mips = RangeMips::build(&g).unwrap();
    let top = mips.levels.last().unwrap();
    let box_lo = top.lo.map(|c| c as f64 * top.side as f64 - 0.5);
    let box_hi: [f64; 3] =
        std::array::from_fn(|k| box_lo[k] + top.dims[k] as f64 * top.side as f64);
    let starts = [
        box_lo,
        box_hi,
        [box_lo[0], 10.0, 12.0],
        [7.5, 7.5, 7.5],
        [15.5, 3.0, 23.5],
        [7.5, -0.5, 12.25],
    ];
    for p in starts {
        for _ in 0..8 {
            let d = random_dir(&mut state);
            for tmax in [40.0, f64::INFINITY] {
                let ray = IndexRay::new(p, d, 0.0, tmax).unwrap();
                check_all_walks(&g, &mips, &ray, &mut state);
            }
            let world = Ray::new(p, d, 0.0, 80.0);
            let index = IndexRay::from_world(&world, g.map()).unwrap();
            let tau = reference_integral(&g, &index, 0.0, 80.0, false);
            let e = estimate(&g, &mips, &world, &params(Estimator::Exact));
            assert_rel(e.transmittance, (-tau).exp(), 1e-9, "boundary start");
        }
    }
}

#[test]
fn far_away_origin() {
    let mut state = Rng::new(5, 0, 0);
    let g = random_grid(
        &mut state,
        [-16, -16, -16],
        [33, 33, 33],
        0.0,
        0.5,
        (0.0, 1.0),
    );
    let mips = RangeMips::build(&g).unwrap();
    for i in 0..12 {
        let target: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 24.0 - 12.0);
        let d = if i < 3 {
            let mut d = [0.0; 3];
            d[i] = 1.0;
            d
        } else {
            random_dir(&mut state)
        };
        let far = 1e7;
        let origin: [f64; 3] = std::array::from_fn(|k| target[k] - far * d[k]);
        let ray = IndexRay::new(origin, d, 0.0, f64::INFINITY).unwrap();
        check_all_walks(&g, &mips, &ray, &mut state);
        // The same line from nearby.
        let near = Ray::new(
            std::array::from_fn(|k| target[k] - 60.0 * d[k]),
            d,
            0.0,
            120.0,
        );
        let index = IndexRay::from_world(&near, g.map()).unwrap();
        let tau = reference_integral(&g, &index, 0.0, 120.0, false);
        let e = estimate(
            &g,
            &mips,
            &Ray::new(origin, d, 0.0, f64::INFINITY),
            &params(Estimator::Exact),
        );
        assert_rel(e.transmittance, (-tau).exp(), 1e-7, "far origin");
    }
}

#[test]
fn infinite_tmax() {
    let mut state = Rng::new(6, 0, 0);
    let zero = random_grid(
        &mut state,
        [-10, -10, -10],
        [21, 21, 21],
        0.0,
        0.5,
        (0.0, 1.0),
    );
    let mips = RangeMips::build(&zero).unwrap();
    let ray = Ray::new(
        [-30.0, 0.3, 0.7],
        unit([1.0, 0.1, -0.05]),
        0.0,
        f64::INFINITY,
    );
    let index = IndexRay::from_world(&ray, zero.map()).unwrap();
    let tau = reference_integral(&zero, &index, 0.0, 200.0, false);
    let exact = estimate(&zero, &mips, &ray, &params(Estimator::Exact));
    assert_rel(exact.transmittance, (-tau).exp(), 1e-9, "infinite tmax");
    let segs: Vec<Segment> = SegmentWalk::new(&mips, &index, 0).unwrap().collect();
    assert_eq!(segs.last().unwrap().t1, f64::INFINITY);
    assert_eq!(segs.last().unwrap().level, LEVEL_OUTSIDE);
    // A non-zero background over an infinite ray: no light gets through.
    let mut fog = zero.clone();
    fog.background = 0.05;
    let mips = RangeMips::build(&fog).unwrap();
    for estimator in [
        Estimator::Exact,
        Estimator::March { step: 0.5 },
        Estimator::Delta,
        Estimator::Ratio,
        Estimator::Residual,
    ] {
        let mut p = params(estimator);
        p.spp = 16;
        let e = estimate(&fog, &mips, &ray, &p);
        assert_eq!(e.transmittance, 0.0, "{estimator:?}");
    }
    // With a zero density scale everything is transparent, infinite or not.
    let mut p = params(Estimator::Exact);
    p.density_scale = 0.0;
    assert_eq!(estimate(&fog, &mips, &ray, &p).transmittance, 1.0);
}

#[test]
fn background_nonzero_finite_tmax() {
    let mut state = Rng::new(7, 0, 0);
    let g = random_grid(
        &mut state,
        [-10, -12, -8],
        [21, 23, 19],
        0.2,
        0.5,
        (0.0, 1.5),
    );
    let mips = RangeMips::build(&g).unwrap();
    let rays = [
        Ray::new([-300.0, 1.0, 2.0], unit([1.0, 0.02, 0.0]), 0.0, 600.0),
        Ray::new([0.5, 0.5, 0.5], unit([0.3, -0.4, 0.5]), -50.0, 400.0),
        // Misses the box: only background.
        Ray::new([0.0, 500.0, 0.0], [1.0, 0.0, 0.0], 10.0, 110.0),
    ];
    for ray in &rays {
        let index = IndexRay::from_world(ray, g.map()).unwrap();
        let tau = 0.01 * reference_integral(&g, &index, ray.tmin, ray.tmax, false);
        let mut p = params(Estimator::Exact);
        p.density_scale = 0.01;
        let exact = estimate(&g, &mips, ray, &p).transmittance;
        assert_rel(exact, (-tau).exp(), 1e-9, "background exact");
        for estimator in [Estimator::Delta, Estimator::Ratio, Estimator::Residual] {
            p.estimator = estimator;
            p.spp = 4000;
            let e = estimate(&g, &mips, ray, &p);
            assert_unbiased(&e, exact, p.spp, &format!("{estimator:?} {ray:?}"));
        }
    }
    assert_rel(
        estimate(&g, &mips, &rays[2], &params(Estimator::Exact)).transmittance,
        (-(0.2f32 as f64) * 100.0).exp(),
        1e-12,
        "background only",
    );
}

#[test]
fn empty_and_reversed_rays() {
    let g = fog_sphere(6.0, 2.0).unwrap();
    let mips = RangeMips::build(&g).unwrap();
    for (tmin, tmax) in [(5.0, 1.0), (3.0, 3.0), (0.0, f64::NEG_INFINITY)] {
        let index = IndexRay::new([-10.0, 0.0, 0.0], [1.0, 0.0, 0.0], tmin, tmax).unwrap();
        assert_eq!(SegmentWalk::new(&mips, &index, 0).unwrap().count(), 0);
        let ray = Ray::new([-10.0, 0.0, 0.0], [1.0, 0.0, 0.0], tmin, tmax);
        for estimator in [Estimator::Exact, Estimator::Delta, Estimator::Residual] {
            assert_eq!(
                estimate(&g, &mips, &ray, &params(estimator)).transmittance,
                1.0
            );
        }
    }
    // A ray grazing the box along an edge has no inside part.
    let top = mips.levels.last().unwrap();
    let corner = top.lo.map(|c| c as f64 * top.side as f64 - 0.5);
    let graze = IndexRay::new(corner, [0.0, 0.0, 1.0], -10.0, 10.0).unwrap();
    let segs: Vec<Segment> = SegmentWalk::new(&mips, &graze, 0).unwrap().collect();
    assert!(segs
        .iter()
        .all(|s| s.range.min == 0.0 && s.range.max == 0.0));
}

#[test]
fn exact_matches_analytic_ramp() {
    // Trilinear interpolation reproduces affine fields, so away from the grid's edges the
    // integral is length times the value at the middle.
    // Dyadic coefficients: every voxel value is exact in f32.
    let (a, b) = (0.5, [1.0 / 64.0, -1.0 / 128.0, 1.0 / 32.0]);
    let mut g = DenseGrid::new([-20, -20, -20], [41, 41, 41], 0.0).unwrap();
    for z in -20..=20 {
        for y in -20..=20 {
            for x in -20..=20 {
                let v = a + b[0] * x as f64 + b[1] * y as f64 + b[2] * z as f64;
                g.set([x, y, z], v as f32);
            }
        }
    }
    let mut state = Rng::new(8, 0, 0);
    for map in [GridMap::IDENTITY, anisotropic_map()] {
        g.map = map;
        let mips = RangeMips::build(&g).unwrap();
        for _ in 0..20 {
            // A chord of the ball of radius 19 in index space: always interior.
            let p: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 16.0 - 8.0);
            let d = random_dir(&mut state);
            let ray = world_ray(&map, p, d, 0.0, 1.0);
            let index = IndexRay::from_world(&ray, &map).unwrap();
            // Longest t keeping index points within radius 19 of the centre: solve |p + t d_i| = 19.
            let di = index.dir;
            let (aa, bb, cc) = (
                di.iter().map(|c| c * c).sum::<f64>(),
                2.0 * (0..3).map(|k| index.origin[k] * di[k]).sum::<f64>(),
                index.origin.iter().map(|c| c * c).sum::<f64>() - 19.0 * 19.0,
            );
            let root = (bb * bb - 4.0 * aa * cc).sqrt();
            let (t0, t1) = ((-bb - root) / (2.0 * aa), (-bb + root) / (2.0 * aa));
            let ray = Ray::new(ray.origin, ray.dir, t0, t1);
            let mid = index.at(0.5 * (t0 + t1));
            let value = a + (0..3).map(|k| b[k] * mid[k]).sum::<f64>();
            let tau = value * (t1 - t0);
            let e = estimate(&g, &mips, &ray, &params(Estimator::Exact));
            assert_rel(e.transmittance, (-tau).exp(), 1e-9, "ramp");
            assert_rel(-e.transmittance.ln(), tau, 1e-9, "ramp tau");
        }
    }
}

#[test]
fn exact_matches_constant_fields() {
    let c = 0.3f32;
    let mut g = DenseGrid::new([-5, 0, 3], [12, 7, 9], c).unwrap();
    g.values.fill(c);
    g.map = anisotropic_map();
    let mips = RangeMips::build(&g).unwrap();
    let mut state = Rng::new(9, 0, 0);
    for filter in [Filter::Trilinear, Filter::Nearest, Filter::Stochastic] {
        for _ in 0..10 {
            let p: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 10.0);
            let ray = world_ray(&g.map, p, random_dir(&mut state), 20.0, 45.0);
            let mut params = params(Estimator::Exact);
            params.density_scale = 1.5;
            params.filter = filter;
            let e = estimate(&g, &mips, &ray, &params);
            assert_rel(
                e.transmittance,
                (-(c as f64) * 1.5 * 45.0).exp(),
                1e-12,
                "constant",
            );
            // The constant field needs no lookups at all.
            assert_eq!(e.lookups, 0);
            params.estimator = Estimator::Ratio;
            assert_rel(
                estimate(&g, &mips, &ray, &params).transmittance,
                e.transmittance,
                1e-12,
                "constant ratio",
            );
        }
    }
}

#[test]
fn exact_matches_brute_force_quadrature() {
    let mut state = Rng::new(10, 0, 0);
    let mut sphere = fog_sphere(14.0, 5.0).unwrap();
    sphere.map = anisotropic_map();
    let mut sparse = random_grid(
        &mut state,
        [-29, -3, -41],
        [37, 26, 30],
        0.0,
        0.4,
        (0.0, 3.0),
    );
    sparse.map = anisotropic_map();
    let plain = random_grid(&mut state, [-9, -9, -9], [19, 19, 19], 0.0, 0.8, (0.0, 1.0));
    for g in [sphere, sparse, plain] {
        let mips = RangeMips::build(&g).unwrap();
        for _ in 0..25 {
            let p: [f64; 3] =
                std::array::from_fn(|k| g.origin[k] as f64 + rng(&mut state) * g.dims[k] as f64);
            let ray = world_ray(
                &g.map,
                p,
                random_dir(&mut state),
                30.0 * rng(&mut state),
                60.0,
            );
            let index = IndexRay::from_world(&ray, &g.map).unwrap();
            for (filter, nearest) in [
                (Filter::Trilinear, false),
                (Filter::Nearest, true),
                // The stochastic filter's exact answer is its mean, the trilinear field.
                (Filter::Stochastic, false),
            ] {
                let tau = 0.05 * reference_integral(&g, &index, 0.0, 60.0, nearest);
                for majorant in [
                    Majorant::Local { level: 0 },
                    Majorant::Local { level: 2 },
                    Majorant::Global,
                ] {
                    let mut p = params(Estimator::Exact);
                    p.density_scale = 0.05;
                    p.filter = filter;
                    p.majorant = majorant;
                    let e = estimate(&g, &mips, &ray, &p);
                    assert_rel(e.transmittance, (-tau).exp(), 1e-9, "quadrature");
                    if tau > 1e-3 {
                        assert_rel(-e.transmittance.ln(), tau, 1e-9, "quadrature tau");
                    }
                }
            }
        }
    }
}

/// The mean of `spp` samples is within 4 standard errors (sample variance) of `exact`.
fn assert_unbiased(e: &Estimate, exact: f64, spp: u32, what: &str) {
    let se = (e.variance / spp as f64).sqrt();
    assert!(
        (e.transmittance - exact).abs() <= 4.0 * se + 1e-12,
        "{what}: mean {} vs exact {exact}, standard error {se}",
        e.transmittance
    );
    assert!(
        se > 0.0 || (e.transmittance - exact).abs() < 1e-12,
        "{what}: no spread"
    );
}

#[test]
fn trackers_are_unbiased() {
    let mut state = Rng::new(11, 0, 0);
    let mut sphere = fog_sphere(16.0, 8.0).unwrap();
    sphere.map = anisotropic_map();
    let sparse = random_grid(
        &mut state,
        [-20, -20, -20],
        [40, 40, 40],
        0.0,
        0.3,
        (0.0, 2.0),
    );
    for (g, scale) in [(&sphere, 0.08), (&sparse, 0.02)] {
        let mips = RangeMips::build(g).unwrap();
        let centre = g.origin.map(|c| c as f64);
        let rays: Vec<Ray> = (0..3)
            .map(|i| {
                let p: [f64; 3] =
                    std::array::from_fn(|k| centre[k] + g.dims[k] as f64 * (0.35 + 0.1 * i as f64));
                world_ray(&g.map, p, random_dir(&mut state), 40.0, 80.0)
            })
            .collect();
        for filter in [Filter::Trilinear, Filter::Stochastic] {
            let mut p = params(Estimator::Exact);
            p.density_scale = scale;
            p.filter = filter;
            let exact = transmittance_batch(g, &mips, &rays, &p).unwrap();
            for estimator in [Estimator::Delta, Estimator::Ratio, Estimator::Residual] {
                for majorant in [
                    Majorant::Local { level: 0 },
                    Majorant::Local { level: 3 },
                    Majorant::Global,
                ] {
                    p.estimator = estimator;
                    p.majorant = majorant;
                    p.spp = 3000;
                    p.seed = 17;
                    let got = transmittance_batch(g, &mips, &rays, &p).unwrap();
                    for (e, x) in got.iter().zip(&exact) {
                        assert!(x.transmittance > 0.05 && x.transmittance < 0.95, "{x:?}");
                        let what = format!("{estimator:?} {majorant:?} {filter:?}");
                        assert_unbiased(e, x.transmittance, p.spp, &what);
                        assert!(e.lookups > 0, "{what}");
                    }
                }
            }
        }
    }
}

#[test]
fn trackers_are_unbiased_to_a_tight_tolerance() {
    // Many samples on rays with T near 0.3, where a bias of 1% of tau would show as about
    // four standard errors per ray; the rays' mean z-score must stay small too.
    let g = fog_sphere(16.0, 10.0).unwrap();
    let mips = RangeMips::build(&g).unwrap();
    let mut state = Rng::new(17, 0, 0);
    let rays: Vec<Ray> = (0..8)
        .map(|_| {
            let p: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 6.0 - 3.0);
            world_ray(&g.map, p, random_dir(&mut state), 30.0, 60.0)
        })
        .collect();
    let mut p = params(Estimator::Exact);
    p.density_scale = 0.06;
    let exact = transmittance_batch(&g, &mips, &rays, &p).unwrap();
    for estimator in [Estimator::Delta, Estimator::Ratio, Estimator::Residual] {
        p.estimator = estimator;
        p.spp = 40_000;
        let got = transmittance_batch(&g, &mips, &rays, &p).unwrap();
        let mut z_sum = 0.0;
        for (e, x) in got.iter().zip(&exact) {
            assert!(x.transmittance > 0.15 && x.transmittance < 0.6, "{x:?}");
            assert_unbiased(e, x.transmittance, p.spp, &format!("{estimator:?}"));
            z_sum += (e.transmittance - x.transmittance) / (e.variance / p.spp as f64).sqrt();
        }
        let z_mean = z_sum / (rays.len() as f64).sqrt();
        assert!(z_mean.abs() < 4.0, "{estimator:?}: pooled z {z_mean}");
    }
}

#[test]
fn nearest_trackers_are_unbiased() {
    let mut state = Rng::new(12, 0, 0);
    let g = random_grid(
        &mut state,
        [-12, -12, -12],
        [24, 24, 24],
        0.0,
        0.5,
        (0.0, 2.0),
    );
    let mips = RangeMips::build(&g).unwrap();
    let ray = world_ray(&g.map, [0.3, -0.2, 0.7], unit([0.4, 0.5, -0.3]), 30.0, 60.0);
    let mut p = params(Estimator::Exact);
    p.filter = Filter::Nearest;
    p.density_scale = 0.05;
    let exact = estimate(&g, &mips, &ray, &p).transmittance;
    for estimator in [Estimator::Delta, Estimator::Ratio, Estimator::Residual] {
        p.estimator = estimator;
        p.spp = 4000;
        let e = estimate(&g, &mips, &ray, &p);
        assert_unbiased(&e, exact, p.spp, &format!("nearest {estimator:?}"));
    }
}

#[test]
fn residual_variance_not_above_ratio_on_smooth_field() {
    let g = fog_sphere(20.0, 16.0).unwrap();
    let mips = RangeMips::build(&g).unwrap();
    let mut state = Rng::new(13, 0, 0);
    for _ in 0..3 {
        let p: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 8.0 - 4.0);
        let ray = world_ray(&g.map, p, random_dir(&mut state), 30.0, 60.0);
        let variance = |estimator| {
            let mut params = params(estimator);
            params.density_scale = 0.1;
            params.spp = 4000;
            estimate(&g, &mips, &ray, &params).variance
        };
        let (ratio, residual) = (variance(Estimator::Ratio), variance(Estimator::Residual));
        assert!(
            residual <= ratio * 1.05,
            "residual {residual} vs ratio {ratio}"
        );
    }
}

#[test]
fn local_majorants_need_fewer_lookups_than_global() {
    let mut state = Rng::new(14, 0, 0);
    let mut g = DenseGrid::new([-60, -60, -60], [120, 120, 120], 0.0).unwrap();
    // A thin dense shell and a hot spot: most of the box is empty.
    for _ in 0..4000 {
        let d = random_dir(&mut state);
        g.set(d.map(|c| (c * 40.0).round() as i64), 1.0);
    }
    g.set([5, 5, 5], 20.0);
    let mips = RangeMips::build(&g).unwrap();
    let ray = Ray::new(
        [-80.0, 1.0, 2.0],
        unit([1.0, 0.05, 0.02]),
        0.0,
        f64::INFINITY,
    );
    let lookups = |majorant| {
        let mut p = params(Estimator::Ratio);
        p.majorant = majorant;
        p.density_scale = 0.1;
        p.spp = 200;
        estimate(&g, &mips, &ray, &p).lookups
    };
    let (fine, coarse, global) = (
        lookups(Majorant::Local { level: 0 }),
        lookups(Majorant::Local { level: 3 }),
        lookups(Majorant::Global),
    );
    assert!(
        fine * 4 < global && fine <= coarse,
        "{fine} {coarse} {global}"
    );
}

#[test]
fn march_converges_quadratically() {
    let g = fog_sphere(12.0, 10.0).unwrap();
    let mips = RangeMips::build(&g).unwrap();
    let ray = Ray::new([-30.0, 1.3, -2.1], unit([1.0, 0.1, 0.2]), 0.0, 70.0);
    let mut p = params(Estimator::Exact);
    p.density_scale = 0.1;
    let exact = estimate(&g, &mips, &ray, &p).transmittance;
    let errors: Vec<f64> = [0.8, 0.4, 0.2, 0.1, 0.05]
        .iter()
        .map(|step| {
            p.estimator = Estimator::March { step: *step };
            (estimate(&g, &mips, &ray, &p).transmittance - exact).abs()
        })
        .collect();
    for w in errors.windows(2) {
        assert!(w[1] < w[0], "{errors:?}");
    }
    // Halving the step four times: an O(step^2) error falls by 256, O(step) by 16.
    assert!(errors[4] < errors[0] / 64.0, "{errors:?}");
    assert!(errors[4] < 1e-5 * exact, "{errors:?}");
}

#[test]
fn batch_is_deterministic_and_matches_single_rays() {
    let g = fog_sphere(10.0, 4.0).unwrap();
    let mips = RangeMips::build(&g).unwrap();
    let mut state = Rng::new(15, 0, 0);
    let rays: Vec<Ray> = (0..40)
        .map(|_| world_ray(&g.map, [0.0; 3], random_dir(&mut state), 20.0, 40.0))
        .collect();
    let mut p = params(Estimator::Delta);
    p.spp = 8;
    p.seed = 3;
    let a = transmittance_batch(&g, &mips, &rays, &p).unwrap();
    let b = transmittance_batch(&g, &mips, &rays, &p).unwrap();
    assert_eq!(a, b);
    for (i, ray) in rays.iter().enumerate() {
        assert_eq!(transmittance(&g, &mips, ray, i as u32, &p).unwrap(), a[i]);
    }
    p.seed = 4;
    assert_ne!(transmittance_batch(&g, &mips, &rays, &p).unwrap(), a);
}

#[test]
fn cell_walk_visits_the_cells_in_order() {
    let mut state = Rng::new(16, 0, 0);
    for i in 0..200 {
        let p: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 20.0 - 10.0);
        let mut d = random_dir(&mut state);
        if i % 4 == 0 {
            d[i % 3] = 0.0;
        }
        let ray = IndexRay::new(p, d, 0.0, 1.0).unwrap();
        let (t0, t1) = (-3.0 * rng(&mut state), 5.0 * rng(&mut state));
        for nearest in [false, true] {
            let pieces: Vec<_> = if nearest {
                CellWalk::nearest(&ray, t0, t1).collect()
            } else {
                CellWalk::trilinear(&ray, t0, t1).collect()
            };
            assert_eq!(pieces[0].t0, t0);
            assert_eq!(pieces.last().unwrap().t1, t1);
            for w in pieces.windows(2) {
                assert_eq!(w[0].t1, w[1].t0);
                let moved: i64 = (0..3).map(|k| (w[1].cell[k] - w[0].cell[k]).abs()).sum();
                assert_eq!(moved, 1, "{w:?}");
            }
            let off = if nearest { -0.5 } else { 0.0 };
            for piece in &pieces {
                let mid = ray.at(0.5 * (piece.t0 + piece.t1));
                for (m, c) in mid.iter().zip(piece.cell) {
                    let lo = c as f64 + off;
                    assert!(*m >= lo - 1e-9 && *m <= lo + 1.0 + 1e-9, "{piece:?}");
                }
            }
        }
    }
}

#[test]
fn bad_parameters_are_errors() {
    let g = fog_sphere(5.0, 2.0).unwrap();
    let mips = RangeMips::build(&g).unwrap();
    let ray = Ray::new([-10.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, 20.0);
    let fails = |p: &TransmittanceParams, ray: &Ray| transmittance(&g, &mips, ray, 0, p).is_err();
    for step in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(fails(&params(Estimator::March { step }), &ray), "{step}");
    }
    let mut p = params(Estimator::Delta);
    p.spp = 0;
    assert!(fails(&p, &ray));
    for scale in [-1.0, f64::NAN, f64::INFINITY] {
        let mut p = params(Estimator::Exact);
        p.density_scale = scale;
        assert!(fails(&p, &ray), "{scale}");
    }
    let mut p = params(Estimator::Exact);
    p.majorant = Majorant::Local {
        level: mips.levels.len(),
    };
    assert!(fails(&p, &ray));
    assert!(SegmentWalk::new(&mips, &IndexRay::from_world(&ray, &g.map).unwrap(), 9).is_err());
    let good = params(Estimator::Exact);
    for bad in [
        Ray::new([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, 1.0),
        Ray::new([f64::INFINITY, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, 1.0),
        Ray::new([0.0; 3], [0.0; 3], 0.0, 1.0),
        Ray::new([0.0; 3], [f64::NAN, 1.0, 0.0], 0.0, 1.0),
        Ray::new([0.0; 3], [1.0, 0.0, 0.0], f64::NEG_INFINITY, 1.0),
        Ray::new([0.0; 3], [1.0, 0.0, 0.0], 0.0, f64::NAN),
    ] {
        assert!(fails(&good, &bad), "{bad:?}");
        assert!(transmittance_batch(&g, &mips, &[ray, bad], &good).is_err());
    }
    // Negative densities stop the trackers, not the exact integral.
    let mut neg = g.clone();
    neg.set([0, 0, 0], -0.5);
    let neg_mips = RangeMips::build(&neg).unwrap();
    for estimator in [Estimator::Delta, Estimator::Ratio, Estimator::Residual] {
        let err = transmittance(&neg, &neg_mips, &ray, 0, &params(estimator)).unwrap_err();
        assert!(err.0.contains("density >= 0"), "{err}");
    }
    assert!(transmittance(&neg, &neg_mips, &ray, 0, &good).is_ok());
    // Mips of another grid.
    let mut other = g.clone();
    other.background = 1.0;
    assert!(transmittance(&other, &mips, &ray, 0, &good).is_err());
}

/// Free-flight sampling (`IndexTransmittance::collision`, what path tracers draw): a ray
/// leaves without a collision with probability equal to the exact transmittance, and
/// collides before `t` with probability `1 - T(t)`, within four standard errors.
#[test]
fn collision_sampling_follows_the_exact_transmittance() {
    let g = fog_sphere(12.0, 4.0).unwrap();
    let mips = RangeMips::build(&g).unwrap();
    let mut p = params(Estimator::Exact);
    p.density_scale = 0.06;
    let exact = IndexTransmittance::new(&g, &mips, &p).unwrap();
    // The sampler ignores the estimator: the same parameters serve.
    let tracker = &exact;
    let ray =
        |t1: f64| IndexRay::new([-20.0, 0.5, -0.25], unit([1.0, 0.1, 0.05]), 0.0, t1).unwrap();
    let t_of = |t1: f64| exact.estimate(&ray(t1), 0).unwrap().transmittance;
    let (t_mid, t_end) = (18.0, 40.0);
    let (all, half) = (t_of(t_end), t_of(t_mid));
    assert!(all > 0.1 && all < 0.9 && half > all, "T = {all}, {half}");
    let n = 20_000;
    let (mut escaped, mut early) = (0, 0);
    for i in 0..n {
        let mut r = Rng::new(7, i, 0);
        match tracker.collision(&ray(t_end), &mut r).unwrap() {
            None => escaped += 1,
            Some(c) => {
                assert!(c.t > 0.0 && c.t < t_end && c.density > 0.0, "{c:?}");
                if c.t < t_mid {
                    early += 1;
                }
            }
        }
    }
    for (what, count, expect) in [
        ("escape", escaped, all),
        ("collide before t_mid", early, 1.0 - half),
    ] {
        let f = count as f64 / n as f64;
        let sigma = (expect * (1.0 - expect) / n as f64).sqrt();
        assert!(
            (f - expect).abs() < 4.0 * sigma,
            "{what}: sampled {f:.4}, exact {expect:.4} (sigma {sigma:.4})"
        );
    }
}
