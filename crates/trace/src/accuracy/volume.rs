//! Accuracy rows: volumes (`crates/volume`).
//!
//! - texel formats: bricked f32/f16/unorm16/unorm8/bc4 and NanoVDB Float/Fp16/Fp8/Fp4/FpN,
//!   all of one grid (the committed `density` fixture, embedded in the binary), against the
//!   f64 trilinear interpolation of its exact source values (`density.npy`);
//! - lookup filters: nearest, trilinear, stochastic on a grid sampled from an analytic
//!   field, against that field;
//! - transmittance estimators on rays through a grid of the same field, against the optical
//!   depth of the trilinear interpolant integrated by our own quadrature;
//! - majorants: density lookups per ray of ratio tracking under local and global bounds.
//!
//! Every reference here is computed by this module's own code ([`Lattice`], [`field`]),
//! never by the lookups or estimators it measures. Grids use the identity map, so index
//! space is world space and `t` is measured in voxels.

use hytrace_volume::{
    parse_nanovdb, sample, sample_trilinear, BrickedGrid, DenseGrid, Estimate, Estimator, Filter,
    IndexRay, IndexTransmittance, Majorant, NanoGrid, RangeMips, Rng, TexelFormat,
    TransmittanceParams, VoxelGrid,
};

use super::{Row, Settings, Timer};

/// `density.npy`: float32 (20, 20, 20), `[a, b, c]` is voxel `DENSITY_ORIGIN + (a, b, c)`
/// (see `tests/data/nanovdb/README.md`).
const DENSITY_NPY: &[u8] = include_bytes!("../../../../tests/data/nanovdb/density.npy");

/// Index coordinate of the first voxel of `density.npy`.
const DENSITY_ORIGIN: [i64; 3] = [-37, -26, -20];

/// Voxels per side of `density.npy`.
const DENSITY_SIDE: usize = 20;

/// The NanoVDB fixtures of `density.npy`: the codec's name and the file's bytes.
const DENSITY_NVDB: [(&str, &[u8]); 5] = [
    (
        "float",
        include_bytes!("../../../../tests/data/nanovdb/density_zip.nvdb"),
    ),
    (
        "fp16",
        include_bytes!("../../../../tests/data/nanovdb/density_fp16.nvdb"),
    ),
    (
        "fp8",
        include_bytes!("../../../../tests/data/nanovdb/density_fp8.nvdb"),
    ),
    (
        "fp4",
        include_bytes!("../../../../tests/data/nanovdb/density_fp4.nvdb"),
    ),
    (
        "fpN, tolerance 0.002",
        include_bytes!("../../../../tests/data/nanovdb/density_fpn.nvdb"),
    ),
];

/// Voxels per side of the grid sampled from [`field`] (origin 0).
const FIELD_SIDE: u32 = 32;

/// Density per unit of [`field`] in the transmittance rows: optical depths of about 0.9 to 3
/// on the rays of [`fog_rays`].
const DENSITY_SCALE: f64 = 0.15;

/// Seed of every random stream of this module.
const SEED: u32 = 0x5eed;

/// The rows of this component.
pub(super) fn rows(settings: Settings) -> crate::Result<Vec<Row>> {
    let timer = Timer::new(settings);
    let mut rows = texel_format_rows(settings, timer)?;
    rows.extend(filter_rows(settings, timer)?);
    let fog = Fog::new(settings)?;
    rows.extend(estimator_rows(&fog, timer)?);
    rows.extend(majorant_rows(&fog, timer)?);
    Ok(rows)
}

/// Voxel values in f64 on a box of index space (x fastest), 0 outside: the source of the
/// references, read with our own trilinear interpolation and quadrature.
struct Lattice {
    origin: [i64; 3],
    dims: [i64; 3],
    values: Vec<f64>,
}

impl Lattice {
    /// The voxels of `grid`, whose background must be 0.
    fn from_dense(grid: &DenseGrid) -> Lattice {
        Lattice {
            origin: grid.origin.map(i64::from),
            dims: grid.dims.map(i64::from),
            values: grid.values.iter().map(|v| f64::from(*v)).collect(),
        }
    }

    fn voxel(&self, ijk: [i64; 3]) -> f64 {
        let mut index = 0;
        for k in (0..3).rev() {
            let local = ijk[k] - self.origin[k];
            if local < 0 || local >= self.dims[k] {
                return 0.0;
            }
            index = index * self.dims[k] + local;
        }
        self.values[index as usize]
    }

    /// The trilinear interpolant at index-space point `p` (voxel centres at integers).
    fn trilinear(&self, p: [f64; 3]) -> f64 {
        let base = p.map(f64::floor);
        let mut sum = 0.0;
        for corner in 0..8 {
            let mut weight = 1.0;
            let mut ijk = [0i64; 3];
            for k in 0..3 {
                let upper = corner >> k & 1 == 1;
                let frac = p[k] - base[k];
                weight *= if upper { frac } else { 1.0 - frac };
                ijk[k] = base[k] as i64 + i64::from(upper);
            }
            sum += weight * self.voxel(ijk);
        }
        sum
    }

    /// The integral of the trilinear interpolant along `ray` over `[tmin, tmax]` (finite).
    /// The interpolant is a cubic in `t` between consecutive crossings of integer planes, so
    /// the ray is cut at every crossing and each piece is integrated by 4-point
    /// Gauss-Legendre, exact for polynomials up to degree 7.
    fn optical_depth(&self, ray: &IndexRay) -> f64 {
        const NODES: [f64; 2] = [0.339_981_043_584_856_3, 0.861_136_311_594_052_6];
        const WEIGHTS: [f64; 2] = [0.652_145_154_862_546_1, 0.347_854_845_137_453_9];
        let mut cuts = vec![ray.tmin, ray.tmax];
        for k in (0..3).filter(|&k| ray.dir[k] != 0.0) {
            let (a, b) = (ray.at(ray.tmin)[k], ray.at(ray.tmax)[k]);
            for plane in a.min(b).ceil() as i64..=a.max(b).floor() as i64 {
                let t = (plane as f64 - ray.origin[k]) / ray.dir[k];
                cuts.push(t.clamp(ray.tmin, ray.tmax));
            }
        }
        cuts.sort_by(f64::total_cmp);
        let mut tau = 0.0;
        for piece in cuts.windows(2) {
            let (mid, half) = (0.5 * (piece[0] + piece[1]), 0.5 * (piece[1] - piece[0]));
            for (x, w) in NODES.iter().zip(WEIGHTS) {
                for t in [mid - half * x, mid + half * x] {
                    tau += w * half * self.trilinear(ray.at(t));
                }
            }
        }
        tau
    }
}

/// Random points uniform in the box `[lo, hi]` per axis.
fn random_points(count: usize, lo: [f64; 3], hi: [f64; 3], stream: u32) -> Vec<[f64; 3]> {
    let mut rng = Rng::new(SEED, stream, 0);
    (0..count)
        .map(|_| std::array::from_fn(|k| lo[k] + (hi[k] - lo[k]) * rng.next_f64()))
        .collect()
}

/// The source values of the density fixtures, from the embedded `density.npy`.
fn density_lattice() -> crate::Result<Lattice> {
    let fail = |why: String| crate::Error::Invalid(format!("embedded density.npy: {why}"));
    let npy = npyz::NpyFile::new(DENSITY_NPY).map_err(|e| fail(e.to_string()))?;
    let n = DENSITY_SIDE;
    if npy.shape() != [n as u64; 3] || npy.order() != npyz::Order::C {
        return Err(fail(format!(
            "expected a C-ordered {n}^3 array, found {:?}",
            npy.shape()
        )));
    }
    let data: Vec<f32> = npy.into_vec().map_err(|e| fail(e.to_string()))?;
    // C order: `[a, b, c]` (a along x) is element `(a * n + b) * n + c`; the lattice is x
    // fastest.
    let mut values = Vec::with_capacity(n * n * n);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                values.push(f64::from(data[(x * n + y) * n + z]));
            }
        }
    }
    Ok(Lattice {
        origin: DENSITY_ORIGIN,
        dims: [n as i64; 3],
        values,
    })
}

/// The `density` grid of a NanoVDB fixture.
fn density_grid(file: &str, bytes: &[u8]) -> crate::Result<NanoGrid> {
    let grid = parse_nanovdb(bytes, file)?
        .grids
        .into_iter()
        .find(|g| g.name() == "density")
        .ok_or_else(|| crate::Error::Invalid(format!("{file}: no grid `density`")))?;
    grid.check_sampleable()?;
    Ok(grid)
}

/// Largest |trilinear lookup - reference| over `points` and the time per lookup (the
/// crate's lookup, blended in f64 from the decoded voxels).
fn lookup_error<G: VoxelGrid>(
    grid: &G,
    reference: &Lattice,
    points: &[[f64; 3]],
    timer: Timer,
) -> (f64, f64) {
    let error = points
        .iter()
        .map(|p| (sample_trilinear(grid, *p) - reference.trilinear(*p)).abs())
        .fold(0.0, f64::max);
    let ns = timer.ns_per_op(points.len(), || {
        points
            .iter()
            .map(|p| sample_trilinear(grid, *p))
            .sum::<f64>()
    });
    (error, ns)
}

/// Texel formats: the bricked formats converted from the fixture's Float grid, and the
/// NanoVDB codecs as the fixtures store them; one grid, one reference for all.
fn texel_format_rows(settings: Settings, timer: Timer) -> crate::Result<Vec<Row>> {
    let reference = density_lattice()?;
    // The interpolant's support: voxel centres plus one voxel of fall-off to the background.
    let lo = reference.origin.map(|c| c as f64 - 1.0);
    let hi = std::array::from_fn(|k| (reference.origin[k] + reference.dims[k]) as f64);
    let points = random_points(settings.size(200_000, 20_000), lo, hi, 1);
    let row = |variant: String, (error, ns_per_op): (f64, f64), memory: u64| Row {
        component: "volume texel format",
        variant,
        metric: "max |trilinear lookup - reference|",
        reference: "f64 trilinear of the source voxels (density.npy)",
        error,
        ns_per_op,
        memory_bytes: Some(memory),
    };
    let nano: Vec<(&str, NanoGrid)> = DENSITY_NVDB
        .iter()
        .map(|(codec, bytes)| density_grid(&format!("density {codec}"), bytes).map(|g| (*codec, g)))
        .collect::<Result<_, _>>()?;
    let float = &nano[0].1;
    let mut rows = Vec::new();
    for format in [
        TexelFormat::F32,
        TexelFormat::F16,
        TexelFormat::Unorm16,
        TexelFormat::Unorm8,
        TexelFormat::Bc4,
    ] {
        let bricked = BrickedGrid::convert(float, format)?;
        rows.push(row(
            format!("bricked {format}"),
            lookup_error(&bricked, &reference, &points, timer),
            bricked.memory_bytes().total() as u64,
        ));
    }
    for (codec, grid) in &nano {
        rows.push(row(
            format!("nanovdb {codec}"),
            lookup_error(grid, &reference, &points, timer),
            grid.buffer_bytes(),
        ));
    }
    Ok(rows)
}

/// The smooth analytic field of the filter, estimator and majorant rows: a Gaussian blob
/// (sigma 7 voxels) centred in the [`FIELD_SIDE`]^3 grid, with ripples of about 8 voxels;
/// positive, at most 1.3.
fn field(p: [f64; 3]) -> f64 {
    let centre = (FIELD_SIDE as f64 - 1.0) / 2.0;
    let q = p.map(|c| c - centre);
    let r2: f64 = q.iter().map(|c| c * c).sum();
    (-r2 / (2.0 * 7.0 * 7.0)).exp()
        * (1.0 + 0.3 * (0.8 * q[0]).sin() * (0.6 * q[1] + 0.5 * q[2]).sin())
}

/// [`field`] sampled at the voxel centres of a [`FIELD_SIDE`]^3 grid at the origin.
fn field_grid() -> crate::Result<DenseGrid> {
    let n = FIELD_SIDE;
    let mut grid = DenseGrid::new([0; 3], [n; 3], 0.0)?;
    for z in 0..i64::from(n) {
        for y in 0..i64::from(n) {
            for x in 0..i64::from(n) {
                grid.set([x, y, z], field([x, y, z].map(|c| c as f64)) as f32);
            }
        }
    }
    Ok(grid)
}

/// Lookup filters on the sampled field, against the field itself, inside the voxel
/// centres' hull (where no lookup reads the background).
fn filter_rows(settings: Settings, timer: Timer) -> crate::Result<Vec<Row>> {
    let grid = field_grid()?;
    let count = settings.size(200_000, 20_000);
    let hi = (FIELD_SIDE - 1) as f64;
    let points = random_points(count, [0.0; 3], [hi; 3], 2);
    // The stochastic filter's uniforms, one triple per point.
    let uniforms = random_points(count, [0.0; 3], [1.0; 3], 3);
    let rows = [
        (Filter::Nearest, "nearest"),
        (Filter::Trilinear, "trilinear"),
        (Filter::Stochastic, "stochastic (one voxel per lookup)"),
    ]
    .into_iter()
    .map(|(filter, variant)| {
        let lookup = |(p, u): (&[f64; 3], &[f64; 3])| sample(&grid, *p, filter, *u);
        let squares: f64 = points
            .iter()
            .zip(&uniforms)
            .map(|(p, u)| (lookup((p, u)) as f64 - field(*p)).powi(2))
            .sum();
        Row {
            component: "volume filter",
            variant: variant.to_string(),
            metric: "RMS |lookup - field|",
            reference: "analytic field",
            error: (squares / count as f64).sqrt(),
            ns_per_op: timer.ns_per_op(count, || {
                points.iter().zip(&uniforms).map(lookup).sum::<f32>()
            }),
            memory_bytes: None,
        }
    })
    .collect();
    Ok(rows)
}

/// The grid, ranges, rays and reference transmittances of the estimator and majorant rows.
/// The transmittance rows' grid, rays and references (shared with the GPU rows).
pub(super) struct Fog {
    /// The grid sampled from [`field`], identity map.
    pub(super) grid: DenseGrid,
    mips: RangeMips,
    /// The rays (index space is world space).
    pub(super) rays: Vec<IndexRay>,
    /// `exp(-tau)` of each ray by [`Lattice::optical_depth`].
    pub(super) reference: Vec<f64>,
}

impl Fog {
    /// The grid, its range mips, the rays and their references.
    pub(super) fn new(settings: Settings) -> crate::Result<Fog> {
        let grid = field_grid()?;
        let mips = RangeMips::build(&grid)?;
        let rays = fog_rays(settings.size(16_000, 400))?;
        let lattice = Lattice::from_dense(&grid);
        let reference = rays
            .iter()
            .map(|r| (-DENSITY_SCALE * lattice.optical_depth(r)).exp())
            .collect();
        Ok(Fog {
            grid,
            mips,
            rays,
            reference,
        })
    }

    /// Every ray's estimate under `params` (one thread) and the time per ray.
    pub(super) fn trace(
        &self,
        params: &TransmittanceParams,
        timer: Timer,
    ) -> crate::Result<(Vec<Estimate>, f64)> {
        let tracer = IndexTransmittance::new(&self.grid, &self.mips, params)?;
        let run = || {
            self.rays
                .iter()
                .enumerate()
                .map(|(i, r)| tracer.estimate(r, i as u32))
                .collect::<Result<Vec<_>, _>>()
        };
        let estimates = run()?;
        Ok((estimates, timer.ns_per_op(self.rays.len(), run)))
    }
}

/// Rays from 40 voxels before to 40 voxels past an aim point uniform in the ball of radius
/// 10 around the grid's centre, in uniform random directions: both ends lie outside the
/// grid, so the rays cross the whole blob.
fn fog_rays(count: usize) -> crate::Result<Vec<IndexRay>> {
    let centre = (FIELD_SIDE as f64 - 1.0) / 2.0;
    let mut rng = Rng::new(SEED, 4, 0);
    (0..count)
        .map(|_| {
            let aim = loop {
                let q: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.next_f64() - 1.0);
                if q.iter().map(|c| c * c).sum::<f64>() <= 1.0 {
                    break q.map(|c| centre + 10.0 * c);
                }
            };
            let z = 1.0 - 2.0 * rng.next_f64();
            let phi = std::f64::consts::TAU * rng.next_f64();
            let s = (1.0 - z * z).max(0.0).sqrt();
            let dir = [s * phi.cos(), s * phi.sin(), z];
            let origin = std::array::from_fn(|k| aim[k] - 40.0 * dir[k]);
            IndexRay::new(origin, dir, 0.0, 80.0).map_err(crate::Error::from)
        })
        .collect()
}

/// Transmittance parameters on the fog rays: trilinear lookups, [`DENSITY_SCALE`].
pub(super) fn fog_params(
    estimator: Estimator,
    spp: u32,
    majorant: Majorant,
) -> TransmittanceParams {
    TransmittanceParams {
        estimator,
        density_scale: DENSITY_SCALE,
        spp,
        seed: SEED,
        filter: Filter::Trilinear,
        majorant,
    }
}

/// Transmittance estimators with local majorants of the 8^3 blocks.
fn estimator_rows(fog: &Fog, timer: Timer) -> crate::Result<Vec<Row>> {
    let local = Majorant::Local { level: 0 };
    let mut variants = vec![(fog_params(Estimator::Exact, 1, local), "exact".to_string())];
    for step in [2.0, 1.0, 0.5, 0.25] {
        let params = fog_params(Estimator::March { step }, 1, local);
        variants.push((params, format!("march, step {step} voxel")));
    }
    for (estimator, name) in [
        (Estimator::Delta, "delta"),
        (Estimator::Ratio, "ratio"),
        (Estimator::Residual, "residual ratio"),
    ] {
        for spp in [1, 4, 16] {
            variants.push((
                fog_params(estimator, spp, local),
                format!("{name}, {spp} spp"),
            ));
        }
    }
    let n = fog.rays.len() as f64;
    let mut rows = Vec::new();
    for (params, mut variant) in variants {
        let (estimates, ns_per_op) = fog.trace(&params, timer)?;
        let errors: Vec<f64> = estimates
            .iter()
            .zip(&fog.reference)
            .map(|(e, r)| e.transmittance - r)
            .collect();
        let bias = errors.iter().sum::<f64>() / n;
        let mean_square = errors.iter().map(|e| e * e).sum::<f64>() / n;
        if matches!(
            params.estimator,
            Estimator::Delta | Estimator::Ratio | Estimator::Residual
        ) {
            // The mean error and its standard error: the trackers are unbiased, so the
            // bias should be within a few standard errors of 0.
            let standard_error = ((mean_square - bias * bias).max(0.0) / n).sqrt();
            variant += &format!(", bias {bias:+.0e} ± {standard_error:.0e}");
        }
        rows.push(Row {
            component: "transmittance estimator",
            variant,
            metric: "RMS |T - T_ref| over rays",
            reference: "our own quadrature of the trilinear interpolant (4-point Gauss-Legendre per cell piece, f64)",
            error: mean_square.sqrt(),
            ns_per_op,
            memory_bytes: None,
        });
    }
    Ok(rows)
}

/// Ratio tracking (4 spp) under local majorants of mip levels 0 to 2 and one global one:
/// the density lookups (tentative collisions) each needs per ray.
fn majorant_rows(fog: &Fog, timer: Timer) -> crate::Result<Vec<Row>> {
    let variants = [
        (Majorant::Local { level: 0 }, "local, 8^3 blocks (level 0)"),
        (Majorant::Local { level: 1 }, "local, 16^3 blocks (level 1)"),
        (Majorant::Local { level: 2 }, "local, 32^3 blocks (level 2)"),
        (Majorant::Global, "global"),
    ];
    let mut rows = Vec::new();
    for (majorant, variant) in variants {
        let (estimates, ns_per_op) =
            fog.trace(&fog_params(Estimator::Ratio, 4, majorant), timer)?;
        let lookups: u64 = estimates.iter().map(|e| e.lookups).sum();
        rows.push(Row {
            component: "majorant",
            variant: variant.to_string(),
            metric: "density lookups per ray (ratio tracking, 4 spp)",
            reference: "exact count",
            error: lookups as f64 / fog.rays.len() as f64,
            ns_per_op,
            memory_bytes: None,
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quick_rows_rank_the_knobs_as_expected() {
        let rows = rows(Settings { quick: true }).unwrap();
        for r in &rows {
            eprintln!(
                "{:24} | {:42} | {:.3e} | {:9.1} ns | {:?}",
                r.component, r.variant, r.error, r.ns_per_op, r.memory_bytes
            );
            assert!(r.error.is_finite() && r.error >= 0.0, "{r:?}");
            assert!(r.ns_per_op.is_finite() && r.ns_per_op > 0.0, "{r:?}");
        }
        let error = |component: &str, prefix: &str| {
            rows.iter()
                .find(|r| r.component == component && r.variant.starts_with(prefix))
                .unwrap_or_else(|| panic!("no row {component} / {prefix}"))
                .error
        };
        let texel = |v: &str| error("volume texel format", v);
        assert!(texel("bricked f32") < 1e-12);
        assert!(texel("nanovdb float") < 1e-12);
        assert!(texel("bricked f32") < texel("bricked f16"));
        assert!(texel("bricked f16") < texel("bricked unorm8"));
        assert!(texel("bricked unorm16") < texel("bricked unorm8"));
        assert!(texel("bricked unorm8") < texel("bricked bc4"));
        assert!(texel("nanovdb fp16") < texel("nanovdb fp8"));
        assert!(texel("nanovdb fp8") < texel("nanovdb fp4"));
        // FpN's stated tolerance bounds each voxel, hence each trilinear blend.
        assert!(texel("nanovdb fpN") <= 0.002 + 1e-6);

        let filter = |v: &str| error("volume filter", v);
        assert!(filter("trilinear") < filter("nearest"));
        assert!(filter("trilinear") < filter("stochastic"));

        let estimator = |v: &str| error("transmittance estimator", v);
        assert!(estimator("exact") < 1e-9);
        let march = ["2", "1", "0.5", "0.25"].map(|s| estimator(&format!("march, step {s} ")));
        assert!(march.windows(2).all(|w| w[1] < w[0]), "{march:?}");
        for tracker in ["delta", "ratio", "residual ratio"] {
            let one = estimator(&format!("{tracker}, 1 spp"));
            let sixteen = estimator(&format!("{tracker}, 16 spp"));
            assert!(sixteen < one, "{tracker}: {one} {sixteen}");
        }
        assert!(estimator("ratio, 16 spp") < estimator("delta, 16 spp"));

        let lookups = |v: &str| error("majorant", v);
        assert!(lookups("local, 8^3") < lookups("local, 32^3"));
        assert!(lookups("local, 32^3") < lookups("global"));
    }
}
