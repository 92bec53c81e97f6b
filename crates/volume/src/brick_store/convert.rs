//! Converting a raw volume file, or any grid, into a brick store in bounded memory.
//!
//! Two sequential passes over the source: the first finds the data's range (the 16-bit codes
//! span it), the second walks it one layer of bricks (8 z-planes) at a time. With the range
//! given, one pass: so a raw volume can come through a pipe (a reconstruction streamed as
//! it is made, or a file decompressed on the fly), read once, its length checked as it
//! ends. A window of
//! three layers is resident: the layer being written and its two neighbours, whose voxels
//! the one-voxel halos of its blocks' ranges read.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;
use std::time::Instant;

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{write_array, write_atomically, TrackedTemporary};
use rayon::prelude::*;

use crate::grid::{Coord, VoxelGrid};

use super::format::{Quantization, StoreMeta, BRICK_SIDE, BRICK_VOXELS, LOD_VALUES, NO_RECORD};
use super::StoreError;

/// Element type of a raw volume file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawType {
    /// Unsigned 8-bit.
    U8,
    /// Unsigned 16-bit.
    U16,
    /// 32-bit IEEE float.
    F32,
}

impl RawType {
    /// Bytes per voxel.
    pub fn size(self) -> usize {
        match self {
            RawType::U8 => 1,
            RawType::U16 => 2,
            RawType::F32 => 4,
        }
    }
}

/// Byte order of a raw volume file's multi-byte voxels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Endian {
    /// Least significant byte first.
    Little,
    /// Most significant byte first.
    Big,
}

/// What a raw volume file holds: voxels x fastest, then y, then z, no header.
#[derive(Clone, Debug, PartialEq)]
pub struct RawSpec {
    /// Voxels along x, y, z.
    pub dims: [u32; 3],
    /// Element type.
    pub dtype: RawType,
    /// Byte order.
    pub endian: Endian,
    /// World size of a voxel along x, y, z.
    pub spacing: [f64; 3],
    /// World position of voxel `(0, 0, 0)`'s centre.
    pub origin: [f64; 3],
}

/// How to convert.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvertOptions {
    /// Value outside the volume and of dropped bricks.
    pub background: f32,
    /// Bricks whose decoded values all lie within this of the background are dropped.
    pub threshold: f32,
    /// The range the codes span; the data's own range when `None` (a first pass finds it).
    /// Values outside it are clamped.
    pub range: Option<[f32; 2]>,
    /// Bytes the converter may hold resident (its window of layers and tables).
    pub memory: u64,
}

/// What a conversion did.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvertReport {
    /// The store's metadata.
    pub meta: StoreMeta,
    /// Bytes of the store's files.
    pub bytes_written: u64,
    /// Bytes of resident memory the conversion planned for (its window and tables).
    pub planned_memory: u64,
    /// Seconds finding the range (0 when it was given).
    pub range_s: f64,
    /// Seconds of the bricking pass.
    pub brick_s: f64,
}

/// Bytes the conversion of a `dims` volume of `dtype` holds resident: three layers of codes,
/// one layer of raw bytes, the superchunk table, the ranges and (at most) every brick's
/// levels of detail.
pub fn planned_memory(dims: [u32; 3], dtype: RawType) -> u64 {
    let plane = dims[0] as u64 * dims[1] as u64;
    let layer = plane * BRICK_SIDE as u64;
    let meta = StoreMeta::for_dims(dims);
    let bricks = meta.bricks().iter().map(|&b| b as u64).product::<u64>();
    let ranges = meta.range_dims().iter().map(|&b| b as u64).product::<u64>() * 8;
    3 * layer * 2
        + layer * dtype.size() as u64
        + meta.table_len() as u64 * 4
        + ranges
        + bricks * (LOD_VALUES as u64 * 4 + 1)
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> StoreError + '_ {
    move |e| StoreError::new(path, e.to_string())
}

/// Converts the raw file `input` into a brick store directory `out` (which must not exist),
/// written through a staging directory renamed into place. `progress` is called with the
/// voxels read so far and the voxels both passes read.
pub fn convert_raw(
    input: &Path,
    spec: &RawSpec,
    options: &ConvertOptions,
    out: &Path,
    progress: &dyn Fn(u64, u64),
) -> Result<ConvertReport, StoreError> {
    validate(input, spec, options, out)?;
    let mut meta = StoreMeta::for_dims(spec.dims);
    meta.matrix = [
        [spec.spacing[0], 0.0, 0.0],
        [0.0, spec.spacing[1], 0.0],
        [0.0, 0.0, spec.spacing[2]],
    ];
    meta.translation = spec.origin;
    meta.source = format!(
        "{} ({:?}, {:?} endian)",
        input
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
        spec.dtype,
        spec.endian
    );
    let open = || RawReader::open(input, spec);
    let planned = planned_memory(spec.dims, spec.dtype);
    write_store(meta, options, planned, open, out, progress)
}

/// Converts the index box of `grid` that holds its data (its blocks' bounding box) into a
/// brick store directory `out` (which must not exist); `name` names the source in errors
/// and in the store's metadata; `progress` as for [`convert_raw`].
pub fn convert_grid(
    grid: &dyn VoxelGrid,
    name: &str,
    options: &ConvertOptions,
    out: &Path,
    progress: &dyn Fn(u64, u64),
) -> Result<ConvertReport, StoreError> {
    let fail = |why: String| StoreError::new(Path::new(name), why);
    let blocks = grid.block_origins().map_err(|e| fail(e.0))?;
    if blocks.is_empty() {
        return Err(fail("the grid holds no data to convert".into()));
    }
    let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
    for b in &blocks {
        for k in 0..3 {
            lo[k] = lo[k].min(i64::from(b[k]));
            hi[k] = hi[k].max(i64::from(b[k]) + BRICK_SIDE as i64);
        }
    }
    let dims = std::array::from_fn(|k| (hi[k] - lo[k]) as u32);
    validate_options(Path::new(name), dims, options, RawType::F32, out)?;
    let mut meta = StoreMeta::for_dims(dims);
    meta.index_origin = lo.map(|c| c as i32);
    meta.matrix = grid.map().matrix;
    meta.translation = grid.map().translation;
    meta.source = name.to_string();
    let origin = meta.index_origin;
    let open = || {
        Ok(GridPlanes {
            grid,
            name,
            origin,
            dims,
            read: 0,
        })
    };
    let planned = planned_memory(dims, RawType::F32);
    write_store(meta, options, planned, open, out, progress)
}

/// Finds the range when it is not given, bricks the source into a staging directory and
/// renames it to `out`.
fn write_store<S: PlaneSource>(
    mut meta: StoreMeta,
    options: &ConvertOptions,
    planned_memory: u64,
    open: impl Fn() -> Result<S, StoreError>,
    out: &Path,
    progress: &dyn Fn(u64, u64),
) -> Result<ConvertReport, StoreError> {
    let voxels = meta.dims.iter().map(|&d| d as u64).product::<u64>();
    let passes = if options.range.is_some() { 1 } else { 2 };
    let done = std::cell::Cell::new(0u64);
    let open = || {
        Ok(Counted {
            inner: open()?,
            done: &done,
            total: voxels * passes,
            progress,
        })
    };
    let t0 = Instant::now();
    let quantization = match options.range {
        Some([lo, hi]) => Quantization::spanning(lo, hi),
        None => {
            let [lo, hi] = data_range(&mut open()?, meta.dims)?;
            Quantization::spanning(lo, hi)
        }
    };
    let range_s = if options.range.is_some() {
        0.0
    } else {
        t0.elapsed().as_secs_f64()
    };
    let t1 = Instant::now();
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(io_error(parent))?;
    let staging = tempfile::Builder::new()
        .prefix(".hytrace-bricks-")
        .tempdir_in(parent)
        .map_err(io_error(parent))?;
    // Listed for the interrupt handler, which runs no destructors.
    let _tracked = TrackedTemporary::new(staging.path());
    meta.background = options.background;
    meta.threshold = options.threshold;
    meta.quantization = quantization;
    let mut source = open()?;
    brick_pass(&mut source, &mut meta, staging.path())?;
    source.finish()?;
    let json = serde_json::to_vec_pretty(&meta).expect("the metadata serializes");
    write_atomically(&staging.path().join("store.json"), |w| w.write_all(&json))
        .map_err(|e| StoreError::new(out, e.to_string()))?;
    let bytes_written = super::store_bytes(staging.path()).map_err(io_error(staging.path()))?;
    std::fs::rename(staging.path(), out).map_err(io_error(out))?;
    // The directory now lives under its final name.
    let _ = staging.keep();
    Ok(ConvertReport {
        meta,
        bytes_written,
        planned_memory,
        range_s,
        brick_s: t1.elapsed().as_secs_f64(),
    })
}

fn validate(
    input: &Path,
    spec: &RawSpec,
    options: &ConvertOptions,
    out: &Path,
) -> Result<(), StoreError> {
    let fail = |why: String| Err(StoreError::new(input, why));
    if spec.dims.contains(&0) {
        return fail(format!(
            "--dims {:?}: every dimension must be at least 1",
            spec.dims
        ));
    }
    if !spec.spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
        return fail(format!(
            "--spacing {:?} must be finite and > 0",
            spec.spacing
        ));
    }
    if !spec.origin.iter().all(|s| s.is_finite()) {
        return fail(format!("--origin {:?} must be finite", spec.origin));
    }
    let voxels = spec.dims.iter().map(|&d| d as u64).product::<u64>();
    let expected = voxels * spec.dtype.size() as u64;
    let file = std::fs::metadata(input).map_err(io_error(input))?;
    if !file.is_file() {
        // A pipe (or another stream) is read once, as it comes, so the range must be
        // given, and its length is checked as it is read.
        if options.range.is_none() {
            return fail(
                "is not a regular file (a pipe?): it can be read only once, so give --range MIN,MAX \
                 (the first pass that finds the data's range needs a second read)"
                    .into(),
            );
        }
        return validate_options(input, spec.dims, options, spec.dtype, out);
    }
    let len = file.len();
    if len != expected {
        return fail(format!(
            "the file has {len} bytes, but --dims {}x{}x{} of {:?} need {expected}",
            spec.dims[0], spec.dims[1], spec.dims[2], spec.dtype
        ));
    }
    validate_options(input, spec.dims, options, spec.dtype, out)
}

/// Checks the options of a conversion of `dims` voxels read as `dtype` from `input`.
fn validate_options(
    input: &Path,
    dims: [u32; 3],
    options: &ConvertOptions,
    dtype: RawType,
    out: &Path,
) -> Result<(), StoreError> {
    let fail = |why: String| Err(StoreError::new(input, why));
    if !options.background.is_finite() || options.threshold.is_nan() || options.threshold < 0.0 {
        return fail(format!(
            "the background ({}) must be finite and the threshold ({}) finite and >= 0",
            options.background, options.threshold
        ));
    }
    if let Some([lo, hi]) = options.range {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return fail(format!("--range {lo},{hi} must be finite with min <= max"));
        }
    }
    let need = planned_memory(dims, dtype);
    if need > options.memory {
        return fail(format!(
            "converting needs {need} bytes resident (three layers of 8 planes, the tables), more than --memory {}",
            options.memory
        ));
    }
    if out.exists() {
        return Err(StoreError::new(
            out,
            "already exists; remove it or choose another output".into(),
        ));
    }
    Ok(())
}

/// A source of voxels read in order (x fastest, then y, then z), as f32.
trait PlaneSource {
    /// Fills `out` with the next `out.len()` voxels; non-finite values are errors.
    fn next(&mut self, out: &mut [f32]) -> Result<(), StoreError>;

    /// After the last voxel: an error when the source holds more than the volume.
    fn finish(&mut self) -> Result<(), StoreError> {
        Ok(())
    }
}

/// A source that reports the voxels read over every pass.
struct Counted<'a, S> {
    inner: S,
    done: &'a std::cell::Cell<u64>,
    total: u64,
    progress: &'a dyn Fn(u64, u64),
}

impl<S: PlaneSource> PlaneSource for Counted<'_, S> {
    fn next(&mut self, out: &mut [f32]) -> Result<(), StoreError> {
        self.inner.next(out)?;
        self.done.set(self.done.get() + out.len() as u64);
        (self.progress)(self.done.get(), self.total);
        Ok(())
    }

    fn finish(&mut self) -> Result<(), StoreError> {
        self.inner.finish()
    }
}

/// The index box `origin .. origin + dims` of a grid, read plane after plane.
struct GridPlanes<'a> {
    grid: &'a dyn VoxelGrid,
    name: &'a str,
    origin: Coord,
    dims: [u32; 3],
    /// Voxels read so far (whole planes).
    read: u64,
}

impl PlaneSource for GridPlanes<'_> {
    fn next(&mut self, out: &mut [f32]) -> Result<(), StoreError> {
        let plane = self.dims[0] as usize * self.dims[1] as usize;
        let z = (self.read / plane as u64) as i32;
        let planes = out.len() / plane;
        let origin = [self.origin[0], self.origin[1], self.origin[2] + z];
        out.par_chunks_mut(plane).enumerate().for_each(|(k, p)| {
            let at = [origin[0], origin[1], origin[2] + k as i32];
            self.grid.read_box(at, [self.dims[0], self.dims[1], 1], p);
        });
        if let Some(i) = out.iter().position(|v| !v.is_finite()) {
            let xyz = [
                origin[0] + (i % self.dims[0] as usize) as i32,
                origin[1] + (i / self.dims[0] as usize % self.dims[1] as usize) as i32,
                origin[2] + (i / plane) as i32,
            ];
            return Err(StoreError::new(
                Path::new(self.name),
                format!("voxel {xyz:?} is {}, not a finite value", out[i]),
            ));
        }
        self.read += (planes * plane) as u64;
        Ok(())
    }
}

/// Reads voxels of the raw file in order, as f32.
struct RawReader<'a> {
    reader: BufReader<File>,
    spec: &'a RawSpec,
    path: &'a Path,
    bytes: Vec<u8>,
    /// Voxels read so far.
    read: u64,
}

impl<'a> RawReader<'a> {
    fn open(path: &'a Path, spec: &'a RawSpec) -> Result<Self, StoreError> {
        let file = File::open(path).map_err(io_error(path))?;
        Ok(RawReader {
            reader: BufReader::with_capacity(1 << 20, file),
            spec,
            path,
            bytes: Vec::new(),
            read: 0,
        })
    }
}

impl PlaneSource for RawReader<'_> {
    fn next(&mut self, out: &mut [f32]) -> Result<(), StoreError> {
        let size = self.spec.dtype.size();
        self.bytes.resize(out.len() * size, 0);
        self.reader
            .read_exact(&mut self.bytes)
            .map_err(io_error(self.path))?;
        let little = self.spec.endian == Endian::Little;
        for (v, b) in out.iter_mut().zip(self.bytes.chunks_exact(size)) {
            *v = match (self.spec.dtype, little) {
                (RawType::U8, _) => f32::from(b[0]),
                (RawType::U16, true) => f32::from(u16::from_le_bytes([b[0], b[1]])),
                (RawType::U16, false) => f32::from(u16::from_be_bytes([b[0], b[1]])),
                (RawType::F32, true) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                (RawType::F32, false) => f32::from_be_bytes([b[0], b[1], b[2], b[3]]),
            };
        }
        if let Some(i) = out.iter().position(|v| !v.is_finite()) {
            let at = self.read + i as u64;
            let plane = self.spec.dims[0] as u64 * self.spec.dims[1] as u64;
            let xyz = [
                at % self.spec.dims[0] as u64,
                at / self.spec.dims[0] as u64 % self.spec.dims[1] as u64,
                at / plane,
            ];
            return Err(StoreError::new(
                self.path,
                format!("voxel {xyz:?} is {}, not a finite value", out[i]),
            ));
        }
        self.read += out.len() as u64;
        Ok(())
    }

    fn finish(&mut self) -> Result<(), StoreError> {
        // A regular file's length was checked before reading; a stream's is checked here.
        let mut byte = [0u8];
        match self.reader.read(&mut byte).map_err(io_error(self.path))? {
            0 => Ok(()),
            _ => Err(StoreError::new(
                self.path,
                format!(
                    "the stream holds more than the {} bytes --dims {}x{}x{} of {:?} need",
                    self.read * self.spec.dtype.size() as u64,
                    self.spec.dims[0],
                    self.spec.dims[1],
                    self.spec.dims[2],
                    self.spec.dtype
                ),
            )),
        }
    }
}

/// The smallest and largest voxel value of the file (first pass).
fn data_range(source: &mut impl PlaneSource, dims: [u32; 3]) -> Result<[f32; 2], StoreError> {
    let total = dims.iter().map(|&d| d as u64).product::<u64>();
    let plane = dims[0] as usize * dims[1] as usize;
    // Whole planes, about a million voxels at a time.
    let mut buffer = vec![0f32; plane * (1usize << 20).div_ceil(plane)];
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    let mut left = total;
    while left > 0 {
        let n = left.min(buffer.len() as u64) as usize;
        source.next(&mut buffer[..n])?;
        for &v in &buffer[..n] {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        left -= n as u64;
    }
    Ok([lo, hi])
}

/// One layer of bricks (8 z-planes): the codes of its voxels (x fastest, planes past the
/// volume's end filled with the background's code) and which of its bricks are kept.
struct Layer {
    codes: Vec<u16>,
    kept: Vec<bool>,
}

/// The resident layers and what a voxel of them decodes to.
struct Window<'a> {
    meta: &'a StoreMeta,
    /// Layers `first ..`, at most three.
    first: i64,
    layers: Vec<Layer>,
}

impl Window<'_> {
    /// The decoded value of voxel `(x, y, z)`: the background outside the volume and in
    /// dropped bricks (the layer of `z` must be resident or outside the volume).
    #[inline]
    fn value(&self, x: i64, y: i64, z: i64) -> f32 {
        let d = self.meta.dims.map(i64::from);
        if x < 0 || y < 0 || z < 0 || x >= d[0] || y >= d[1] || z >= d[2] {
            return self.meta.background;
        }
        let b = BRICK_SIDE as i64;
        let layer = &self.layers[(z / b - self.first) as usize];
        let bricks_x = self.meta.bricks()[0] as i64;
        if !layer.kept[((y / b) * bricks_x + x / b) as usize] {
            return self.meta.background;
        }
        let code = layer.codes[(((z % b) * d[1] + y) * d[0] + x) as usize];
        self.meta.quantization.decode(code)
    }
}

/// The second pass: reads layer after layer, writes the kept bricks, their levels of detail,
/// the superchunk table and the ranges into `dir`; sets the counts in `meta`.
fn brick_pass(
    source: &mut impl PlaneSource,
    meta: &mut StoreMeta,
    dir: &Path,
) -> Result<(), StoreError> {
    let bricks = meta.bricks();
    let [nx, ny, nz] = meta.dims.map(|d| d as usize);
    let plane = nx * ny;
    let bin_path = dir.join("bricks.bin");
    let mut bin = BufWriter::with_capacity(
        1 << 20,
        File::create(&bin_path).map_err(io_error(&bin_path))?,
    );
    let mut table = vec![NO_RECORD; meta.table_len()];
    let mut lods: Vec<f32> = Vec::new();
    let range_dims = meta.range_dims();
    let mut ranges: Vec<f32> = Vec::with_capacity(range_dims.iter().product::<usize>() * 2);
    let mut raw = vec![0f32; plane * BRICK_SIDE];
    let mut records = 0u64;
    let mut window = Window {
        meta,
        first: 0,
        layers: Vec::new(),
    };
    let layers = bricks[2] as i64;
    // Block layer j's ranges need brick layers j - 1 ..= j + 1; layers -1 and `layers` are
    // the ring of blocks around the bricks.
    for j in -1..=layers {
        let next = j + 1;
        if next < layers {
            let planes = (nz - next as usize * BRICK_SIDE).min(BRICK_SIDE);
            source.next(&mut raw[..planes * plane])?;
            window.layers.push(read_layer(window.meta, &raw, planes));
        }
        while window.first < j - 1 && !window.layers.is_empty() {
            window.layers.remove(0);
            window.first += 1;
        }
        if (0..layers).contains(&j) {
            write_layer(&window, j, &mut bin, &mut table, &mut lods, &mut records)
                .map_err(io_error(&bin_path))?;
        }
        ranges.extend(layer_ranges(&window, j));
    }
    bin.flush().map_err(io_error(&bin_path))?;
    let total = bricks.iter().map(|&b| b as u64).product::<u64>();
    meta.kept_bricks = records;
    meta.dropped_bricks = total - records;
    let s = meta.superchunks();
    let fail = |e: hytrace_foundry::FoundryError| StoreError::new(dir, e.to_string());
    write_array(
        &dir.join("superchunks.npy"),
        Scalar::U32,
        &[s[2] as u64, s[1] as u64, s[0] as u64, 4096],
        bytemuck::cast_slice(&table),
    )
    .map_err(fail)?;
    write_array(
        &dir.join("brick_lod.npy"),
        Scalar::F32,
        &[records, LOD_VALUES as u64],
        bytemuck::cast_slice(&lods),
    )
    .map_err(fail)?;
    let r = range_dims.map(|d| d as u64);
    write_array(
        &dir.join("ranges.npy"),
        Scalar::F32,
        &[r[2], r[1], r[0], 2],
        bytemuck::cast_slice(&ranges),
    )
    .map_err(fail)?;
    Ok(())
}

/// Quantizes a layer of `planes` z-planes and decides which of its bricks are kept.
fn read_layer(meta: &StoreMeta, raw: &[f32], planes: usize) -> Layer {
    let q = meta.quantization;
    let [nx, ny, _] = meta.dims.map(|d| d as usize);
    let plane = nx * ny;
    let mut codes = vec![q.encode(meta.background); plane * BRICK_SIDE];
    codes[..planes * plane]
        .par_iter_mut()
        .zip(&raw[..planes * plane])
        .for_each(|(c, &v)| *c = q.encode(v));
    let [bx, by, _] = meta.bricks();
    let (bg, threshold) = (meta.background, meta.threshold);
    let kept = (0..bx * by)
        .into_par_iter()
        .map(|k| {
            let (x0, y0) = (k % bx * BRICK_SIDE, k / bx * BRICK_SIDE);
            (0..planes).any(|z| {
                (y0..(y0 + BRICK_SIDE).min(ny)).any(|y| {
                    let row = (z * ny + y) * nx;
                    codes[row + x0..row + (x0 + BRICK_SIDE).min(nx)]
                        .iter()
                        .any(|&c| (q.decode(c) - bg).abs() > threshold)
                })
            })
        })
        .collect();
    Layer { codes, kept }
}

/// Appends layer `j`'s kept bricks (codes and levels of detail) and records them in the
/// superchunk table.
fn write_layer(
    window: &Window,
    j: i64,
    bin: &mut impl Write,
    table: &mut [u32],
    lods: &mut Vec<f32>,
    records: &mut u64,
) -> std::io::Result<()> {
    let meta = window.meta;
    let [bx, by, _] = meta.bricks();
    let layer = &window.layers[(j - window.first) as usize];
    let [nx, ny, _] = meta.dims.map(|d| d as usize);
    let fill = meta.quantization.encode(meta.background);
    let mut brick = [0u16; BRICK_VOXELS];
    for k in (0..bx * by).filter(|&k| layer.kept[k]) {
        let (x0, y0) = (k % bx * BRICK_SIDE, k / bx * BRICK_SIDE);
        let z0 = j as usize * BRICK_SIDE;
        let mut sums = [0f64; LOD_VALUES];
        for (i, code) in brick.iter_mut().enumerate() {
            let (x, y, z) = (i % 8, i / 8 % 8, i / 64);
            let inside = x0 + x < nx && y0 + y < ny && z0 + z < meta.dims[2] as usize;
            *code = if inside {
                layer.codes[(z * ny + y0 + y) * nx + x0 + x]
            } else {
                fill
            };
            let value = f64::from(if inside {
                meta.quantization.decode(*code)
            } else {
                meta.background
            });
            sums[0] += value;
            sums[1 + (x / 4) + 2 * (y / 4) + 4 * (z / 4)] += value;
        }
        bin.write_all(bytemuck::cast_slice(&brick.map(u16::to_le)))?;
        lods.push((sums[0] / BRICK_VOXELS as f64) as f32);
        lods.extend(sums[1..].iter().map(|s| (s / 64.0) as f32));
        table[meta.table_slot([k % bx, k / bx, j as usize])] = *records as u32;
        *records += 1;
    }
    Ok(())
}

/// The halo-inclusive ranges of block layer `j` (x fastest, blocks -1 ..= bricks on x and
/// y), as min, max pairs.
fn layer_ranges(window: &Window, j: i64) -> Vec<f32> {
    let [bx, by, _] = window.meta.bricks().map(|b| b as i64);
    let b = BRICK_SIDE as i64;
    let width = bx + 2;
    let blocks = ((by + 2) * width) as usize;
    let ranges: Vec<[f32; 2]> = (0..blocks)
        .into_par_iter()
        .map(|k| {
            let (cx, cy) = (k as i64 % width - 1, k as i64 / width - 1);
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for z in j * b - 1..=j * b + b {
                for y in cy * b - 1..=cy * b + b {
                    for x in cx * b - 1..=cx * b + b {
                        let v = window.value(x, y, z);
                        lo = lo.min(v);
                        hi = hi.max(v);
                    }
                }
            }
            [lo, hi]
        })
        .collect();
    ranges.into_iter().flatten().collect()
}
