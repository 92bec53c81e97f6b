//! Build steps: the table of WGSL modules under `shaders/` (so a new module needs no list
//! edited by hand), and the Embree 3 link when the `embree` feature is on (default builds
//! need no Embree).
//!
//! The Embree library is the system's `libembree3` (Debian: `libembree-dev`); set
//! `EMBREE_DIR` to an installation prefix whose `lib` holds it to link another one.

use std::path::{Path, PathBuf};

/// Every `.wgsl` file below `dir`, as (module name, absolute path), sorted by name.
fn wgsl_modules(root: &Path, dir: &Path, out: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            wgsl_modules(root, &path, out);
        } else if path.extension().is_some_and(|e| e == "wgsl") {
            let rel = path.strip_prefix(root).expect("below the shader root");
            let name = rel.with_extension("").to_string_lossy().replace('\\', "/");
            out.push((name, path.canonicalize().expect("readable shader path")));
        }
    }
}

fn write_module_table() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let shaders = manifest.join("../../shaders");
    println!("cargo:rerun-if-changed={}", shaders.display());
    let mut modules = Vec::new();
    wgsl_modules(&shaders, &shaders, &mut modules);
    modules.sort();
    let mut table = String::from("&[\n");
    for (name, path) in &modules {
        table.push_str(&format!(
            "    ({name:?}, include_str!({:?})),\n",
            path.display().to_string()
        ));
    }
    table.push_str("]\n");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets it"));
    std::fs::write(out.join("wgsl_modules.rs"), table).expect("OUT_DIR is writable");
}

fn main() {
    write_module_table();
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    if std::env::var_os("CARGO_FEATURE_EMBREE").is_none() {
        return;
    }
    if let Some(dir) = std::env::var_os("EMBREE_DIR") {
        let lib = Path::new(&dir).join("lib");
        println!("cargo:rustc-link-search=native={}", lib.display());
    }
    println!("cargo:rustc-link-lib=dylib=embree3");
}
