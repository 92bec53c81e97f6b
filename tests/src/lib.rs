//! Helpers for the cross-crate and oracle tests: finding the Python oracle environment and
//! running the Geant4 oracle.

pub mod gdml;
pub mod geant4;
pub mod vdb;

use std::path::PathBuf;
use std::process::Command;

/// The Python interpreter of the oracle environment (`HYTRACE_PYTHON`, set by
/// `scripts/test.sh`), or `None` with the reason printed. With `HYTRACE_REQUIRE_ORACLES=1` a
/// missing interpreter or module panics, so CI cannot pass by skipping oracle tests.
pub fn oracle_python(modules: &[&str]) -> Option<PathBuf> {
    let required = std::env::var("HYTRACE_REQUIRE_ORACLES").as_deref() == Ok("1");
    let fail = |why: String| {
        if required {
            panic!("HYTRACE_REQUIRE_ORACLES=1 but {why}");
        }
        eprintln!("SKIPPED: oracle test needs {why}; run scripts/test.sh");
        None
    };
    let Some(python) = std::env::var_os("HYTRACE_PYTHON").map(PathBuf::from) else {
        return fail("HYTRACE_PYTHON to name the oracle environment's python".to_string());
    };
    let import = format!(
        "import {}",
        if modules.is_empty() {
            "sys".to_string()
        } else {
            modules.join(", ")
        }
    );
    match Command::new(&python)
        .args(["-c", &import])
        .env("GEANT4_DATA_DIR", geant4_data_dir())
        .output()
    {
        Ok(out) if out.status.success() => Some(python),
        Ok(out) => fail(format!(
            "{} to import {modules:?}: {}",
            python.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        )),
        Err(e) => fail(format!("{} to run: {e}", python.display())),
    }
}

/// An existing empty directory for `GEANT4_DATA_DIR`, so that importing geant4_pybind
/// neither downloads physics data nor asks for it (geometry queries need none).
pub fn geant4_data_dir() -> PathBuf {
    let dir = std::env::temp_dir().join("hytrace-geant4-data");
    std::fs::create_dir_all(&dir).expect("creating the Geant4 data directory");
    dir
}

/// Runs a Python script with arguments in the oracle environment; panics with its stderr on
/// failure.
pub fn run_python(python: &PathBuf, script: &str, args: &[&str]) -> String {
    let out = Command::new(python)
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "python failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// A float64 `.npy` array: shape and values.
pub fn f64_array(path: &std::path::Path) -> (Vec<u64>, Vec<f64>) {
    use hytrace_foundry::layout::Scalar;
    let a = hytrace_foundry::npy::read_array(path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(a.scalar, Scalar::F64, "{}", path.display());
    (a.shape, bytemuck::pod_collect_to_vec(&a.bytes))
}
