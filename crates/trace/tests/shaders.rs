//! Every WGSL file under shaders/ is registered with the composer, and every registered
//! module composes and passes naga's full validation.

use std::path::{Path, PathBuf};

use hytrace_trace::gpu::compose::{compose_with, MODULES};

fn wgsl_files(dir: &Path, root: &Path, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            wgsl_files(&path, root, out);
        } else if path.extension().is_some_and(|e| e == "wgsl") {
            let rel = path.strip_prefix(root).unwrap().with_extension("");
            out.push(rel.to_string_lossy().replace('\\', "/"));
        }
    }
}

#[test]
fn every_wgsl_file_is_a_registered_module() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shaders");
    let mut files = Vec::new();
    wgsl_files(&root, &root, &mut files);
    for f in &files {
        assert!(
            MODULES.iter().any(|(n, _)| n == f),
            "shaders/{f}.wgsl is not in compose::MODULES"
        );
        let on_disk = std::fs::read_to_string(root.join(format!("{f}.wgsl"))).unwrap();
        let embedded = MODULES.iter().find(|(n, _)| n == f).unwrap().1;
        assert_eq!(on_disk, embedded, "{f}: embedded copy differs (rebuild)");
    }
    assert_eq!(
        files.len(),
        MODULES.len(),
        "a registered module has no file"
    );
}

/// Composes `name` with the features `enabled` picks and validates it with naga.
fn validates(name: &str, enabled: &dyn Fn(&str) -> bool) {
    let source = compose_with(name, enabled).unwrap();
    let module = naga::front::wgsl::parse_str(&source)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
}

#[test]
fn every_module_composes_and_validates_with_naga() {
    for (name, _) in MODULES {
        validates(name, &|_| true);
    }
}

/// A module must import what it uses itself: with every feature left out, no helper
/// arrives through a feature's imports (a scene with media only once composed a render
/// kernel whose scene walk called a helper only the CSG and mesh modules imported).
#[test]
fn every_module_composes_and_validates_with_no_feature() {
    for (name, _) in MODULES {
        validates(name, &|_| false);
    }
}
