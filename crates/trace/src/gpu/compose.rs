//! A small WGSL composer: kernels name the modules they need with `// #import NAME` lines and
//! get one source with every module once, dependencies first. All modules are compiled into
//! the binary from `shaders/`, so no algorithm is written twice in WGSL.

/// Every WGSL module, by name (its path under `shaders/` without `.wgsl`).
pub const MODULES: &[(&str, &str)] = &[
    ("foundry", include_str!("../../../../shaders/foundry.wgsl")),
    (
        "scene_bindings",
        include_str!("../../../../shaders/scene_bindings.wgsl"),
    ),
    (
        "transform",
        include_str!("../../../../shaders/transform.wgsl"),
    ),
    (
        "kernels/foundry_probe",
        include_str!("../../../../shaders/kernels/foundry_probe.wgsl"),
    ),
];

/// The modules a source imports, in the order written.
pub fn imports(source: &str) -> impl Iterator<Item = &str> {
    source
        .lines()
        .filter_map(|l| l.trim().strip_prefix("// #import "))
        .map(str::trim)
}

/// The composed source of module `root`: its imports (transitively, each once, dependencies
/// first), then the module itself.
pub fn compose(root: &str) -> Result<String, String> {
    fn visit<'a>(
        name: &'a str,
        chain: &mut Vec<&'a str>,
        done: &mut Vec<&'a str>,
        out: &mut String,
    ) -> Result<(), String> {
        if done.contains(&name) {
            return Ok(());
        }
        if chain.contains(&name) {
            return Err(format!("import cycle: {} -> {name}", chain.join(" -> ")));
        }
        let (name, source) = MODULES.iter().find(|(n, _)| *n == name).ok_or_else(|| {
            format!(
                "unknown module `{name}` (imported by `{}`)",
                chain.last().unwrap_or(&"?")
            )
        })?;
        chain.push(name);
        for dep in imports(source) {
            visit(dep, chain, done, out)?;
        }
        chain.pop();
        out.push_str(&format!("// ---- module {name} ----\n{source}\n"));
        done.push(name);
        Ok(())
    }
    let mut out = String::new();
    visit(root, &mut Vec::new(), &mut Vec::new(), &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn imports_come_first_and_once() {
        let src = compose("kernels/foundry_probe").unwrap();
        let foundry = src.find("// ---- module foundry ----").unwrap();
        let kernel = src
            .find("// ---- module kernels/foundry_probe ----")
            .unwrap();
        assert!(foundry < kernel);
        assert_eq!(src.matches("// ---- module foundry ----").count(), 1);
        assert!(compose("no_such_module")
            .unwrap_err()
            .contains("unknown module"));
    }
}
