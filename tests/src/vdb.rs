//! The OpenVDB/NanoVDB oracle: grids built from NumPy arrays by pyopenvdb (Debian's
//! python3-openvdb), converted by `nanovdb_convert` (libnanovdb-tools), with NumPy
//! references of lookups and optical depths (tests/oracle/vdb_oracle.py).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The oracle script.
pub fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("oracle/vdb_oracle.py")
}

/// Debian's interpreter with pyopenvdb (`HYTRACE_VDB_PYTHON`, default /usr/bin/python3)
/// when it and `nanovdb_convert` work, else `None` with the reason printed; with
/// `HYTRACE_REQUIRE_ORACLES=1` their absence panics, so CI cannot pass by skipping.
pub fn vdb_python() -> Option<PathBuf> {
    let required = std::env::var("HYTRACE_REQUIRE_ORACLES").as_deref() == Ok("1");
    let python = std::env::var_os("HYTRACE_VDB_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/python3"));
    let checks = [
        Command::new(&python)
            .args(["-c", "import pyopenvdb, numpy"])
            .output(),
        Command::new("nanovdb_convert").arg("--version").output(),
    ];
    for (what, check) in ["python3-openvdb", "libnanovdb-tools"].iter().zip(checks) {
        let ok = matches!(&check, Ok(out) if out.status.success());
        if !ok {
            let why = format!(
                "{what} ({} with pyopenvdb, nanovdb_convert)",
                python.display()
            );
            if required {
                panic!("HYTRACE_REQUIRE_ORACLES=1 but {why} is missing: run scripts/test.sh");
            }
            eprintln!("SKIPPED: volume oracle test needs {why}; run scripts/test.sh");
            return None;
        }
    }
    Some(python)
}

/// Runs the oracle script with `args`; panics with its stderr on failure.
pub fn run_oracle(python: &Path, args: &[&str]) {
    let out = Command::new(python)
        .arg(script())
        .args(args)
        .output()
        .expect("the VDB oracle runs");
    assert!(
        out.status.success(),
        "vdb_oracle.py {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The directory of oracle grids (made once per test process), or `None` when the oracle
/// is not installed (see [`vdb_python`]).
pub fn oracle_cases() -> Option<&'static (PathBuf, PathBuf)> {
    static CASES: OnceLock<Option<(PathBuf, PathBuf)>> = OnceLock::new();
    CASES
        .get_or_init(|| {
            let python = vdb_python()?;
            let dir = tempfile::Builder::new()
                .prefix("hytrace-vdb-oracle")
                .tempdir()
                .expect("temporary directory")
                .keep();
            run_oracle(&python, &["make", dir.to_str().unwrap()]);
            Some((python, dir))
        })
        .as_ref()
}

/// One oracle case: its metadata (tests/oracle/vdb_oracle.py `make`).
#[derive(Debug, serde::Deserialize)]
pub struct CaseMeta {
    /// Index coordinate of the dense array's first voxel.
    pub origin: [i32; 3],
    /// Background value.
    pub background: f32,
    /// Index-to-world linear part, rows, as given to OpenVDB (which may store it rounded).
    pub matrix: [[f64; 3]; 3],
    /// Index-to-world translation.
    pub translation: [f64; 3],
    /// Index points and their world positions by OpenVDB's transform.
    pub map_samples: Vec<([f64; 3], [f64; 3])>,
    /// Active voxels pyopenvdb reports.
    pub active_voxels: u64,
    /// Files written, by representation (`vdb`, `nanovdb`, `nanovdb_fp8`, ...; null when the
    /// tool could not write it).
    pub files: std::collections::BTreeMap<String, Option<String>>,
}

/// Reads case `name`'s metadata and dense values (float32, axes x y z) from `dir`.
pub fn case(dir: &Path, name: &str) -> (CaseMeta, Vec<u64>, Vec<f32>) {
    let text = std::fs::read_to_string(dir.join(format!("{name}.json"))).unwrap();
    let meta: CaseMeta = serde_json::from_str(&text).unwrap();
    let a = hytrace_foundry::npy::read_array(&dir.join(format!("{name}.npy")))
        .unwrap_or_else(|e| panic!("{e}"));
    (meta, a.shape, bytemuck::pod_collect_to_vec(&a.bytes))
}

/// The names of the oracle cases.
pub const CASES: [&str; 3] = ["sparse", "far", "background"];
