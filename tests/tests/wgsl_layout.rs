//! The generated WGSL files (`shaders/generated/foundry.wgsl` from the Foundry's records,
//! `shaders/generated/trace_records.wgsl` from the tracers') are current, valid, and lay
//! out every shared struct exactly as Rust does (naga computes WGSL's layout independently
//! of our generators).

use std::path::PathBuf;

use hytrace_foundry::layout::Field;

type Entry = (&'static str, usize, &'static [Field]);

/// Checks that `relative` (from the workspace root) holds `fresh`, or rewrites it when
/// `HYTRACE_BLESS` is set.
fn check_current(relative: &str, fresh: &str) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(relative);
    if std::env::var_os("HYTRACE_BLESS").is_some() {
        std::fs::write(&path, fresh).unwrap();
        return;
    }
    let on_disk = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        on_disk == fresh,
        "{} is stale: run `HYTRACE_BLESS=1 cargo test -p hytrace-tests --test wgsl_layout`",
        path.display()
    );
}

#[test]
fn generated_wgsl_is_current() {
    check_current(
        hytrace_foundry::wgsl::GENERATED_PATH,
        &hytrace_foundry::wgsl::generate(),
    );
    check_current(
        hytrace_trace::gpu::records::GENERATED_PATH,
        &hytrace_trace::gpu::records::generate(),
    );
}

#[test]
fn naga_layout_matches_rust_layout() {
    check_layouts(
        &hytrace_foundry::wgsl::generate(),
        &hytrace_foundry::wgsl::gpu_records(),
    );
    // The tracers' records follow the Foundry's (the file is read after foundry.wgsl).
    let both = hytrace_foundry::wgsl::generate() + &hytrace_trace::gpu::records::generate();
    let mut all = hytrace_foundry::wgsl::gpu_records();
    all.extend(hytrace_trace::gpu::records::gpu_records());
    check_layouts(&both, &all);
}

/// `wgsl` parses and validates, declares exactly the structs of `records`, and lays each
/// out as Rust does.
fn check_layouts(wgsl: &str, records: &[Entry]) {
    let module = naga::front::wgsl::parse_str(wgsl).expect("generated WGSL parses");
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .expect("generated WGSL validates");
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).unwrap();

    for (name, size, fields) in records {
        let (handle, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(*name))
            .unwrap_or_else(|| panic!("struct {name} missing from the WGSL"));
        let naga::TypeInner::Struct { members, span } = &ty.inner else {
            panic!("{name} is not a struct")
        };
        assert_eq!(
            *span as usize, *size,
            "{name}: WGSL size differs from size_of"
        );
        // In a storage array the stride is the size rounded up to the alignment.
        let align = layouter[handle].alignment.round_up(*span) as usize;
        assert_eq!(
            align, *size,
            "{name}: array stride in WGSL differs from size_of"
        );
        assert_eq!(members.len(), fields.len(), "{name}: member count");
        for (m, f) in members.iter().zip(fields.iter()) {
            assert_eq!(m.name.as_deref(), Some(f.name), "{name}: member order");
            assert_eq!(m.offset as usize, f.offset, "{name}.{}: offset", f.name);
            assert_eq!(
                layouter[m.ty].size as usize,
                f.size(),
                "{name}.{}: size",
                f.name
            );
        }
    }
    // Every struct the WGSL declares has a Rust twin.
    for (_, ty) in module.types.iter() {
        if let (Some(n), naga::TypeInner::Struct { .. }) = (&ty.name, &ty.inner) {
            assert!(
                records.iter().any(|(r, _, _)| r == n),
                "WGSL struct {n} has no Rust twin"
            );
        }
    }
}

#[test]
fn typecodes_in_wgsl_match_rust() {
    let module = naga::front::wgsl::parse_str(&hytrace_foundry::wgsl::generate()).unwrap();
    let mut seen = 0;
    for (_, c) in module.constants.iter() {
        let name = c.name.as_deref().unwrap_or("");
        let value = match module.global_expressions[c.init] {
            naga::Expression::Literal(naga::Literal::U32(v)) => v,
            ref e => panic!("{name}: unexpected initializer {e:?}"),
        };
        if let Some(code) = hytrace_foundry::TypeCode::ALL
            .iter()
            .find(|c| c.wgsl_name() == name)
        {
            assert_eq!(value, *code as u32, "{name}");
            seen += 1;
        }
    }
    assert_eq!(seen, hytrace_foundry::TypeCode::ALL.len());
}
