//! Test data files found on disk.

use std::path::{Path, PathBuf};

/// Every file under `dir` (its subdirectories included) whose extension is `ext`, sorted.
pub fn files_with_extension(dir: &Path, ext: &str) -> Vec<PathBuf> {
    fn walk(dir: &Path, ext: &str, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, ext, out);
            } else if p.extension().is_some_and(|x| x == ext) {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(dir, ext, &mut files);
    files.sort();
    files
}

/// The shared public GDML corpus: `HYTRACE_GDML_DIR`, else `../shared/gdml` beside the
/// repository. Panics when it is missing: the tests over it must not pass by finding
/// nothing.
pub fn shared_gdml_dir() -> PathBuf {
    let dir = std::env::var_os("HYTRACE_GDML_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/gdml"));
    assert!(
        dir.is_dir(),
        "{}: the shared GDML files are missing (set HYTRACE_GDML_DIR)",
        dir.display()
    );
    dir
}

/// Every `.gdml` file of [`shared_gdml_dir`], sorted; panics when there is none.
pub fn shared_gdml_files() -> Vec<PathBuf> {
    let dir = shared_gdml_dir();
    let files = files_with_extension(&dir, "gdml");
    assert!(!files.is_empty(), "{}: no GDML files", dir.display());
    files
}
