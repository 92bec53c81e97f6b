//! A Foundry as a directory of `.npy` files plus `meta.json`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{FoundryError, Result};
use crate::layout::Record;
use crate::npy::{read_records, write_atomically, write_records};
use crate::store::Foundry;

/// Value of `format` in `meta.json`.
pub const FORMAT_NAME: &str = "hytrace-foundry";
/// Version of the directory layout; bumped whenever a record changes.
pub const FORMAT_VERSION: u32 = 3;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Meta {
    format: String,
    version: u32,
    solid_names: Vec<String>,
}

/// Every array of the store with its file stem, for code that treats them uniformly.
macro_rules! for_each_array {
    ($f:expr, $apply:ident) => {{
        $apply!($f, solid);
        $apply!($f, prim);
        $apply!($f, node);
        $apply!($f, node64);
        $apply!($f, plan);
        $apply!($f, plan64);
        $apply!($f, tran);
        $apply!($f, itra);
        $apply!($f, inst);
        $apply!($f, inst_tran);
        $apply!($f, inst_mother);
        $apply!($f, tri);
        $apply!($f, brick);
    }};
}

/// File names of a Foundry directory, `meta.json` last.
pub fn file_names() -> Vec<String> {
    let mut names = Vec::new();
    macro_rules! name {
        ($f:expr, $array:ident) => {
            names.push(concat!(stringify!($array), ".npy").to_string())
        };
    }
    for_each_array!((), name);
    names.push("optics.json".to_string());
    names.push("meta.json".to_string());
    names
}

/// Whether `dir` holds a `meta.json` of this format (any version), i.e. was written by
/// [`Foundry::save`] and may be replaced.
fn is_foundry_dir(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join("meta.json"))
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
        .is_some_and(|meta| meta["format"] == FORMAT_NAME)
}

impl Foundry {
    /// Validates the store and writes it to `dir` (created or replaced as a whole: the files
    /// are written into a temporary directory beside it, which is then renamed). An existing
    /// `dir` is replaced only if it is a Foundry directory; anything else is left untouched
    /// and reported as an error.
    pub fn save(&self, dir: &Path) -> Result<()> {
        self.validate()?;
        if dir.exists() && !is_foundry_dir(dir) {
            return Err(FoundryError::File {
                path: dir.to_path_buf(),
                problem: "exists and is not a Foundry directory (no hytrace meta.json); refusing to replace it".to_string(),
            });
        }
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| FoundryError::Io { path, source }
        };
        let parent = match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(io(&parent))?;
        let staging = tempfile::Builder::new()
            .prefix(".hytrace-foundry-")
            .tempdir_in(&parent)
            .map_err(io(&parent))?;
        let _tracked = crate::npy::TrackedTemporary::new(staging.path());
        macro_rules! save {
            ($f:expr, $array:ident) => {
                write_records(
                    &staging.path().join(concat!(stringify!($array), ".npy")),
                    &$f.$array,
                )?
            };
        }
        for_each_array!(self, save);
        write_atomically(&staging.path().join("optics.json"), |w| {
            serde_json::to_writer(&mut *w, &self.optics).map_err(std::io::Error::other)?;
            w.write_all(b"\n")
        })?;
        let meta = Meta {
            format: FORMAT_NAME.to_string(),
            version: FORMAT_VERSION,
            solid_names: self.solid_names.clone(),
        };
        write_atomically(&staging.path().join("meta.json"), |w| {
            serde_json::to_writer_pretty(&mut *w, &meta).map_err(std::io::Error::other)?;
            w.write_all(b"\n")
        })?;
        let staged = staging.keep();
        if dir.exists() {
            let old = tempfile::Builder::new()
                .prefix(".hytrace-old-")
                .tempdir_in(&parent)
                .map_err(io(&parent))?
                .keep();
            std::fs::rename(dir, old.join("previous")).map_err(io(dir))?;
            std::fs::rename(&staged, dir).map_err(io(dir))?;
            std::fs::remove_dir_all(&old).map_err(io(&old))?;
        } else {
            std::fs::rename(&staged, dir).map_err(io(dir))?;
        }
        Ok(())
    }

    /// Loads a directory written by [`Foundry::save`] (or by NumPy with the same dtypes) and
    /// validates it; an error names the file, the record and the field at fault.
    pub fn load(dir: &Path) -> Result<Foundry> {
        let meta_path = dir.join("meta.json");
        let text = std::fs::read_to_string(&meta_path).map_err(|source| FoundryError::Io {
            path: meta_path.clone(),
            source,
        })?;
        let meta: Meta = serde_json::from_str(&text).map_err(|e| FoundryError::File {
            path: meta_path.clone(),
            problem: format!("not a Foundry meta file: {e}"),
        })?;
        if meta.format != FORMAT_NAME || meta.version != FORMAT_VERSION {
            return Err(FoundryError::File {
                path: meta_path,
                problem: format!(
                    "format `{}` version {}, this build reads `{FORMAT_NAME}` version {FORMAT_VERSION}",
                    meta.format, meta.version
                ),
            });
        }
        let mut f = Foundry {
            solid_names: meta.solid_names,
            ..Foundry::default()
        };
        macro_rules! load {
            ($f:expr, $array:ident) => {
                $f.$array = read_records(&dir.join(concat!(stringify!($array), ".npy")))?
            };
        }
        for_each_array!(f, load);
        let optics_path = dir.join("optics.json");
        let text = std::fs::read_to_string(&optics_path).map_err(|source| FoundryError::Io {
            path: optics_path.clone(),
            source,
        })?;
        f.optics = serde_json::from_str(&text).map_err(|e| FoundryError::File {
            path: optics_path.clone(),
            problem: format!("not a Foundry optics file: {e}"),
        })?;
        f.validate().map_err(|e| e.in_directory(dir))?;
        Ok(f)
    }

    /// Bytes of what only the CPU keeps: the double-precision originals, the placement
    /// hierarchy and `optics.json`.
    pub fn cpu_only_bytes(&self) -> usize {
        let arrays: [&[u8]; 5] = [
            bytemuck::cast_slice(&self.node64),
            bytemuck::cast_slice(&self.plan64),
            bytemuck::cast_slice(&self.tran),
            bytemuck::cast_slice(&self.inst_tran),
            bytemuck::cast_slice(&self.inst_mother),
        ];
        let optics = serde_json::to_vec(&self.optics).map_or(0, |v| v.len());
        arrays.iter().map(|a| a.len()).sum::<usize>() + optics
    }

    /// Bytes of each GPU-visible array, in binding order (see [`gpu_arrays`]).
    pub fn gpu_array_bytes(&self) -> [&[u8]; 8] {
        [
            bytemuck::cast_slice(&self.solid),
            bytemuck::cast_slice(&self.prim),
            bytemuck::cast_slice(&self.node),
            bytemuck::cast_slice(&self.plan),
            bytemuck::cast_slice(&self.itra),
            bytemuck::cast_slice(&self.inst),
            bytemuck::cast_slice(&self.tri),
            bytemuck::cast_slice(&self.brick),
        ]
    }
}

/// The arrays the GPU receives, in binding order, as (binding name, record type name).
pub fn gpu_arrays() -> [(&'static str, &'static str); 8] {
    use crate::records::*;
    [
        ("solid", Solid::NAME),
        ("prim", Prim::NAME),
        ("node", Node::NAME),
        ("plan", Plane::NAME),
        ("itra", Transform::NAME),
        ("inst", Instance::NAME),
        ("tri", Triangle::NAME),
        ("brick", Brick::NAME),
    ]
}
