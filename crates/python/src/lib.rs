//! Python bindings of hytrace: the `hytrace._hytrace` extension module of the `hytrace`
//! package (built by maturin, see `pyproject.toml` and `docs/python.md`).
//!
//! Every function calls the library the command line calls ([`hytrace_trace`]), on NumPy
//! arrays instead of `.npy` files, so its results equal the command's bit for bit. Rays
//! and points are checked as the command checks them, with its messages. Tracing runs with
//! the GIL released. Errors are raised as the package's exceptions
//! (`hytrace/_errors.py`): `HytraceError` and its subclasses for bad input, missing
//! files and failures of the library.

mod arrays;
mod errors;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_trace::error::report;
use hytrace_trace::gpu::TexelStore;
use hytrace_trace::photons::gensteps::{GenstepFile, GENSTEP_COLUMNS};
use hytrace_trace::photons::run::{prepare, propagate_in};
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::tracer::Precision as PhotonPrecision;
use hytrace_trace::photons::{load_photon_scene, Origin, PhotonScene, RunOptions};
use hytrace_trace::render::run::{parse_size, render, RenderBackend, RenderSettings};
use hytrace_trace::render::spec::RenderSpec;
use hytrace_trace::scan::{self, Backend, Precision, RAY_COLUMNS};
use hytrace_trace::scene::load_render_scene;
use hytrace_trace::volume::{self, EstimatorOptions, Represented};
use hytrace_volume::DEFAULT_STORE_BUDGET;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyAny;

use arrays::{float_rows, ray_rows};
use errors::{choice, library_error, open_error, value_error};

/// The JSON text `value` as a Python object (dicts, lists, numbers, strings).
fn to_python<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?
        .call_method1("loads", (value.to_string(),))
}

/// A photon run's wavelength as Python gives it: nanometres, or `MATERIAL:PROPERTY`.
#[derive(FromPyObject)]
enum WavelengthArg {
    Nm(f64),
    Spectrum(String),
}

/// A scene loaded once and traced many times: `hytrace.load(path)`.
#[pyclass(frozen, module = "hytrace")]
struct Scene {
    /// What it was loaded from (`default` for the embedded scene).
    path: PathBuf,
    /// Whether unsupported GDML elements were skipped.
    lenient: bool,
    foundry: Foundry,
    /// The scene's render description (its file's, or the defaults).
    render_spec: RenderSpec,
    /// Prepared on the first photon run and again when a run asks for another memory
    /// budget: the scene read again with what finds the optical surface of every crossing
    /// (GDML), its property tables and its media, with the budget it was prepared for.
    photon_scene: Mutex<Option<(u64, Arc<PhotonScene>)>>,
}

impl Scene {
    fn options(&self) -> GdmlOptions {
        GdmlOptions {
            lenient: self.lenient,
        }
    }

    /// The scene prepared for photons, each medium read as stored holding at most `memory`
    /// bytes resident (`hytrace photons --memory`): the one prepared last when it was
    /// prepared with that budget, else prepared again (a budget too small for a store is
    /// refused naming it).
    fn photon_scene(&self, memory: u64) -> hytrace_trace::Result<Arc<PhotonScene>> {
        // A poisoned lock only means a run panicked: the scene it holds is whole.
        let mut slot = self.photon_scene.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((budget, scene)) = slot.as_ref() {
            if *budget == memory {
                return Ok(Arc::clone(scene));
            }
        }
        let (f, surfaces) = load_photon_scene(&self.path, &self.options())?;
        let scene = Arc::new(prepare(
            &f,
            surfaces,
            &self.path,
            PhotonPrecision::F64,
            memory,
        )?);
        *slot = Some((memory, Arc::clone(&scene)));
        Ok(scene)
    }
}

/// The columns of a genstep row, for messages.
const GENSTEP_COLUMN_NAMES: &str =
    "kind, photons, material, t0, x0, y0, z0, x1, y1, z1, beta0, beta1, charge, component";

/// Loads a scene: `"default"` (the embedded default scene), a Foundry directory, a
/// `.toml` scene file, a `.gdml` file or an `.obj`, `.gltf` or `.glb` mesh, as
/// `hytrace info` reads it. With `lenient`, GDML elements this build does not support are
/// skipped with a warning instead of failing.
#[pyfunction]
#[pyo3(signature = (path = PathBuf::from("default"), *, lenient = false))]
fn load(py: Python<'_>, path: PathBuf, lenient: bool) -> PyResult<Scene> {
    let options = GdmlOptions { lenient };
    let (foundry, render_spec) = py
        .detach(|| load_render_scene(Some(&path), &options))
        .map_err(|e| match path.as_os_str() == "default" {
            true => library_error(e),
            false => open_error(&path)(e),
        })?;
    Ok(Scene {
        path,
        lenient,
        foundry,
        render_spec,
        photon_scene: Mutex::new(None),
    })
}

#[pymethods]
impl Scene {
    /// What the scene was loaded from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "hytrace.Scene({:?}: {} solids, {} instances)",
            self.path.display().to_string(),
            self.foundry.solid_names.len(),
            self.foundry.inst.len()
        )
    }

    /// The scene's summary, as `hytrace info --json` prints it.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &hytrace_trace::report::summary(&self.foundry))
    }

    /// The first boundary crossing of each ray, as `hytrace scan` computes it.
    ///
    /// `rays`: (N, 8) float32 or float64, `ox oy oz tmin dx dy dz tmax` (a C-contiguous
    /// float64 array is read in place). Returns `(hits, ids)`: hits (N, 4) `nx ny nz t`
    /// (float32 for `precision="f32"`, float64 for `"f64"`; `t = inf` on a miss) and ids
    /// (N, 3) int32 `instance boundary copy` (-1 on a miss).
    #[pyo3(signature = (rays, *, precision = "f32", backend = "cpu"))]
    fn scan<'py>(
        &self,
        py: Python<'py>,
        rays: &Bound<'py, PyAny>,
        precision: &str,
        backend: &str,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let precision: Precision = choice("precision", precision)?;
        let backend: Backend = choice("backend", backend)?;
        let rows = float_rows::<8>(rays, "rays", RAY_COLUMNS)?;
        let rows = rows.rows();
        let f = &self.foundry;
        let result = py
            .detach(|| {
                let rays = ray_rows(rows)?;
                scan::scan_with(f, &rays, precision, backend)
                    .map(|(result, _)| result)
                    .map_err(library_error)
            })
            .map_err(|e| e.into_pyerr())?;
        let n = result.hits.len();
        let hits = match precision {
            Precision::F32 => arrays::matrix(py, result.hits_f32(), n, 4)?,
            Precision::F64 => arrays::matrix(py, bytemuck::cast_vec::<_, f64>(result.hits), n, 4)?,
        };
        let ids = arrays::matrix(py, bytemuck::cast_vec::<_, i32>(result.ids), n, 3)?;
        Ok((hits, ids))
    }

    /// The transmittance of the scene's media along each ray up to its first surface
    /// crossing (to `tmax` on a miss), as `hytrace scan --transmittance` computes it:
    /// (N,) float64. The options are the command's (`--estimator` ...); ray `i` draws the
    /// random streams of index `first + i`.
    #[pyo3(signature = (
        rays, *, estimator = "exact", step = 0.5, spp = 1, seed = 0, density_scale = 1.0,
        filter = "trilinear", level = 0, global_majorant = false, precision = "f32",
        backend = "cpu", first = 0
    ))]
    #[allow(clippy::too_many_arguments)]
    fn transmittance<'py>(
        &self,
        py: Python<'py>,
        rays: &Bound<'py, PyAny>,
        estimator: &str,
        step: f64,
        spp: u32,
        seed: u32,
        density_scale: f64,
        filter: &str,
        level: usize,
        global_majorant: bool,
        precision: &str,
        backend: &str,
        first: u32,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let options = estimator_options(
            (estimator, filter),
            (step, spp, seed, density_scale),
            (level, global_majorant),
        )?;
        let precision: Precision = choice("precision", precision)?;
        let backend: Backend = choice("backend", backend)?;
        let rows = float_rows::<8>(rays, "rays", RAY_COLUMNS)?;
        let rows = rows.rows();
        let f = &self.foundry;
        let params = options.args().params();
        let run = py
            .detach(|| {
                let rays = ray_rows(rows)?;
                scan::scan_transmittance_on(f, &rays, precision, &params, backend, first)
                    .map_err(library_error)
            })
            .map_err(|e| e.into_pyerr())?;
        Ok(PyArray1::from_vec(py, run.values))
    }

    /// Renders the scene as `hytrace render` does, returning the image: (H, W, 3) float32
    /// linear radiance, rows from the top. Each option overrides the scene's own:
    /// `size` as `(width, height)` or `"WIDTHxHEIGHT"`; `memory`: bytes each medium read as
    /// stored in a brick store may hold resident (its cache; on the GPU its brick pool), as
    /// `--memory`.
    #[pyo3(signature = (
        *, size = None, spp = None, view = None, volumes = None, max_bounces = None,
        step = None, seed = None, transparent = Vec::new(), backend = "cpu",
        gpu_texels = "storage", memory = None
    ))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        size: Option<&Bound<'py, PyAny>>,
        spp: Option<u32>,
        view: Option<&str>,
        volumes: Option<&str>,
        max_bounces: Option<u32>,
        step: Option<f64>,
        seed: Option<u32>,
        transparent: Vec<String>,
        backend: &str,
        gpu_texels: &str,
        memory: Option<u64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let size = match size {
            None => None,
            Some(s) => {
                let text = match s.extract::<(i64, i64)>() {
                    Ok((w, h)) => format!("{w}x{h}"),
                    Err(_) => s.extract::<String>()?,
                };
                Some(parse_size(&text).map_err(|e| value_error(format!("size {e}")))?)
            }
        };
        let settings = RenderSettings {
            size,
            spp,
            view: view.map(|v| choice("view", v)).transpose()?,
            volumes: volumes.map(|v| choice("volumes", v)).transpose()?,
            max_bounces,
            step,
            seed,
            memory,
            transparent,
            cutaway: Default::default(),
            detector: Default::default(),
        };
        let backend: RenderBackend = choice("backend", backend)?;
        let texels: TexelStore = choice("gpu_texels", gpu_texels)?;
        let f = &self.foundry;
        let mut spec = self.render_spec.clone();
        settings
            .apply(f, &mut spec)
            .map_err(|e| value_error(report(&e)))?;
        let rendered = py
            .detach(|| render(f, &spec, backend, texels, &|_| {}))
            .map_err(library_error)?;
        let image = rendered.image;
        let flat: Vec<f32> = bytemuck::cast_vec(image.pixels);
        let shape = [image.height as usize, image.width as usize, 3];
        Ok(PyArray1::from_vec(py, flat).reshape(shape)?.into_any())
    }

    /// Propagates optical photons from `source` through the scene as `hytrace photons`
    /// does, photons `first .. first + photons` (photon `i` draws the random stream
    /// `(seed, i)`, so runs over consecutive ranges give together what one run gives);
    /// `wavelength` in nanometres, or `"MATERIAL:PROPERTY"` to draw each photon's from that
    /// spectrum of a scene material. With `gensteps` (a `(G, 14)` array of Cherenkov and
    /// scintillation steps, the layout of `hytrace photons --gensteps`) instead of a
    /// source, the photons they emit (`photons` defaults to all from `first` on).
    /// `memory`: bytes each medium read as stored in a brick store may hold resident (its
    /// tables and a cache of the bricks photons read), as `--memory`; a budget too small
    /// for a store raises `HytraceError` naming it. The results do not depend on it.
    ///
    /// Returns the detected photons, (H, 16) float64 with the columns of the command's
    /// output; with `histories=True`, `(hits, histories)` where histories is every photon's
    /// packed step history, (photons,) uint64.
    #[pyo3(signature = (
        source = None, photons = None, *, gensteps = None, wavelength = WavelengthArg::Nm(420.0),
        seed = 0, max_steps = 10_000, first = 0, histories = false, memory = DEFAULT_STORE_BUDGET
    ))]
    #[allow(clippy::too_many_arguments)]
    fn photons<'py>(
        &self,
        py: Python<'py>,
        source: Option<&str>,
        photons: Option<u64>,
        gensteps: Option<&Bound<'py, PyAny>>,
        wavelength: WavelengthArg,
        seed: u32,
        max_steps: u32,
        first: u64,
        histories: bool,
        memory: u64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let origin = match (source, gensteps) {
            (Some(source), None) => {
                let source = Source::parse(source).map_err(library_error)?;
                let wavelength = match wavelength {
                    WavelengthArg::Nm(nm) => Wavelength::Fixed(nm),
                    WavelengthArg::Spectrum(text) => {
                        Wavelength::parse(&text).map_err(library_error)?
                    }
                };
                Origin::Torch { source, wavelength }
            }
            (None, Some(g)) => {
                let rows = float_rows::<GENSTEP_COLUMNS>(g, "gensteps", GENSTEP_COLUMN_NAMES)?;
                let values: &[f64] = bytemuck::cast_slice(rows.rows());
                let shape = [rows.rows().len() as u64, GENSTEP_COLUMNS as u64];
                let file = GenstepFile::from_values("gensteps".into(), &shape, values)
                    .map_err(library_error)?;
                Origin::Gensteps(Arc::new(file))
            }
            _ => return Err(value_error("give a source or gensteps, not both".into()).into()),
        };
        let scene = py
            .detach(|| self.photon_scene(memory))
            .map_err(library_error)?;
        let photons = match (photons, &origin) {
            (Some(n), _) => n,
            (None, Origin::Gensteps(file)) => {
                let total = file
                    .photons(&self.foundry.optics.materials)
                    .map_err(library_error)?;
                if total <= first {
                    let e = format!("the gensteps emit {total} photons, none from first={first}");
                    return Err(value_error(e).into());
                }
                total - first
            }
            (None, Origin::Torch { .. }) => {
                let e = "photons: the number of photons is needed with a source";
                return Err(value_error(e.into()).into());
            }
        };
        let options = RunOptions {
            origin,
            photons,
            first,
            seed,
            max_steps,
            keep_histories: histories,
            records: 0,
        };
        let run = py
            .detach(|| propagate_in(&scene, &self.path, &options, &|_| ()))
            .map_err(library_error)?;
        let n = run.hits.len();
        let rows: Vec<[f64; 16]> = run.hits.into_iter().map(|h| h.0).collect();
        let hits = arrays::matrix(py, bytemuck::cast_vec::<_, f64>(rows), n, 16)?;
        if histories {
            let codes = PyArray1::from_vec(py, run.histories).into_any();
            Ok((hits, codes).into_pyobject(py)?.into_any())
        } else {
            Ok(hits)
        }
    }
}

/// A sparse volume: one grid of a NanoVDB (`.nvdb`) or OpenVDB (`.vdb`) file, a brick store
/// directory (read through a cache of at most `memory` bytes, as `--memory`) or a
/// procedural grid (`sphere:RADIUS[,VOXEL[,BLEND]]`, `box:W,H,D[,VOXEL[,BLEND]]`), in the
/// representation `repr` (as `hytrace volume sample --repr`; `None`: the file's own).
#[pyclass(frozen, module = "hytrace")]
struct Volume {
    spec: String,
    grid: Represented,
    memory: u64,
}

/// The estimator options of a `transmittance` method's keywords (the commands' flags):
/// the estimator and filter names, then step, spp, seed and density scale, then the
/// majorants' level and whether one global majorant is used.
fn estimator_options(
    (estimator, filter): (&str, &str),
    (step, spp, seed, density_scale): (f64, u32, u32, f64),
    (level, global_majorant): (usize, bool),
) -> PyResult<EstimatorOptions> {
    Ok(EstimatorOptions {
        estimator: choice("estimator", estimator)?,
        step,
        spp,
        seed,
        density_scale,
        filter: choice("filter", filter)?,
        level,
        global_majorant,
    })
}

/// Whether `spec` names a volume file (`.nvdb`, `.vdb`) rather than a procedural grid.
fn is_volume_file(spec: &str) -> bool {
    let extension = Path::new(spec).extension().and_then(|e| e.to_str());
    !hytrace_volume::is_procedural(spec)
        && extension
            .is_some_and(|e| e.eq_ignore_ascii_case("nvdb") || e.eq_ignore_ascii_case("vdb"))
}

#[pymethods]
impl Volume {
    #[new]
    #[pyo3(signature = (path, *, grid = None, repr = None, memory = DEFAULT_STORE_BUDGET))]
    fn new(
        py: Python<'_>,
        path: &Bound<'_, PyAny>,
        grid: Option<&str>,
        repr: Option<&str>,
        memory: u64,
    ) -> PyResult<Self> {
        let spec = match path.extract::<PathBuf>() {
            Ok(p) => p.display().to_string(),
            Err(_) => path.extract::<String>()?,
        };
        let repr = repr.map(|r| choice("repr", r)).transpose()?;
        let represented = py
            .detach(|| {
                let (_, g) = volume::open_within(&spec, grid, memory)?;
                volume::represent(g, repr)
            })
            .map_err(|e| match is_volume_file(&spec) {
                true => open_error(Path::new(&spec))(e),
                false => library_error(e),
            })?;
        Ok(Volume {
            spec,
            grid: represented,
            memory,
        })
    }

    fn __repr__(&self) -> String {
        format!("hytrace.Volume({:?})", self.spec)
    }

    /// The file's grids (names, value types, bounding boxes, voxel counts, memory per
    /// representation), as `hytrace volume info --json` prints them.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let spec = &self.spec;
        let info = py.detach(|| volume::info(spec)).map_err(library_error)?;
        to_python(py, &info)
    }

    /// Looks the grid up at `points`, (N, 3) float32 or float64, as `hytrace volume sample`
    /// does: (N,) float32 values, or with `majorant=LEVEL` the local majorant at that mip
    /// level of the block holding each point. Point `i` of a stochastic lookup draws the
    /// random stream `(seed, i)`.
    #[pyo3(signature = (points, *, filter = "trilinear", space = "world", seed = 0, majorant = None))]
    fn sample<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        filter: &str,
        space: &str,
        seed: u32,
        majorant: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let filter: volume::FilterArg = choice("filter", filter)?;
        let space: volume::Space = choice("space", space)?;
        let rows = float_rows::<3>(points, "points", "")?;
        let points = rows.rows();
        volume::check_points(points, "points").map_err(|e| value_error(report(&e)))?;
        let grid = &self.grid;
        let values = py
            .detach(|| match majorant {
                Some(level) => volume::majorants(grid, points, space, level),
                None => Ok(volume::sample_points(
                    grid.grid(),
                    points,
                    space,
                    filter.into(),
                    seed,
                )),
            })
            .map_err(library_error)?;
        // A brick store whose file failed after it opened read the background: no answer.
        grid.check_reads().map_err(library_error)?;
        Ok(PyArray1::from_vec(py, values))
    }

    /// The transmittance along each world ray, (N, 8) float32 or float64 (`ox oy oz tmin dx
    /// dy dz tmax`), as `hytrace volume transmittance` computes it: (N,) float64. The
    /// options are the command's; ray `i` draws the random streams of index `i`. On
    /// `backend="gpu"` a brick store streams through a brick pool of at most the volume's
    /// `memory` bytes of device memory.
    #[pyo3(signature = (
        rays, *, estimator = "exact", step = 0.5, spp = 1, seed = 0, density_scale = 1.0,
        filter = "trilinear", level = 0, global_majorant = false, backend = "cpu"
    ))]
    #[allow(clippy::too_many_arguments)]
    fn transmittance<'py>(
        &self,
        py: Python<'py>,
        rays: &Bound<'py, PyAny>,
        estimator: &str,
        step: f64,
        spp: u32,
        seed: u32,
        density_scale: f64,
        filter: &str,
        level: usize,
        global_majorant: bool,
        backend: &str,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let options = estimator_options(
            (estimator, filter),
            (step, spp, seed, density_scale),
            (level, global_majorant),
        )?;
        let backend: volume::VolumeBackend = choice("backend", backend)?;
        let rows = float_rows::<8>(rays, "rays", RAY_COLUMNS)?;
        let rows = rows.rows();
        let (grid, memory) = (&self.grid, self.memory);
        let run = py
            .detach(|| {
                let rays = ray_rows(rows)?;
                let args = options.args();
                volume::transmittances_on(grid, &rays, &args, backend, TexelStore::Storage, memory)
                    .map_err(library_error)
            })
            .map_err(|e| e.into_pyerr())?;
        // A brick store whose file failed after it opened read the background: no answer.
        grid.check_reads().map_err(library_error)?;
        let values = run.estimates.iter().map(|e| e.transmittance).collect();
        Ok(PyArray1::from_vec(py, values))
    }
}

/// The extension module: `Scene`, `Volume` and `load`, re-exported by the `hytrace`
/// package.
#[pymodule]
fn _hytrace(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add_class::<Volume>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
