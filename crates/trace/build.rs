//! Links Embree 3 when the `embree` feature is on; default builds need nothing.
//!
//! The library is the system's `libembree3` (Debian: `libembree-dev`); set `EMBREE_DIR` to
//! an installation prefix whose `lib` holds it to link another one.

fn main() {
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    if std::env::var_os("CARGO_FEATURE_EMBREE").is_none() {
        return;
    }
    if let Some(dir) = std::env::var_os("EMBREE_DIR") {
        let lib = std::path::Path::new(&dir).join("lib");
        println!("cargo:rustc-link-search=native={}", lib.display());
    }
    println!("cargo:rustc-link-lib=dylib=embree3");
}
