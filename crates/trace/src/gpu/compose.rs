//! A small WGSL composer: kernels name the modules they need with `// #import NAME` lines and
//! get one source with every module once, dependencies first. All modules are compiled into
//! the binary from `shaders/`, so no algorithm is written twice in WGSL.
//!
//! Lines between `// #if FEATURE` and `// #endif` (not nested) are kept only when the
//! feature is on, imports included: a scene without meshes gets no mesh code, one without
//! a torus no quartic solver ([`compose_with`]).

/// Every WGSL module, by name (its path under `shaders/` without `.wgsl`), found by the
/// build script and compiled into the binary.
pub const MODULES: &[(&str, &str)] = include!(concat!(env!("OUT_DIR"), "/wgsl_modules.rs"));

/// The modules a source imports, in the order written.
pub fn imports(source: &str) -> impl Iterator<Item = &str> {
    source
        .lines()
        .filter_map(|l| l.trim().strip_prefix("// #import "))
        .map(str::trim)
}

/// `source` without the `#if` blocks of features that are off.
fn preprocess(name: &str, source: &str, enabled: &dyn Fn(&str) -> bool) -> Result<String, String> {
    let mut out = String::with_capacity(source.len());
    let mut block: Option<(&str, bool)> = None;
    for line in source.lines() {
        let trimmed = line.trim();
        if let Some(feature) = trimmed.strip_prefix("// #if ") {
            if let Some((open, _)) = block {
                return Err(format!(
                    "module `{name}`: `#if {feature}` inside `#if {open}`"
                ));
            }
            let feature = feature.trim();
            block = Some((feature, enabled(feature)));
            continue;
        }
        if trimmed == "// #endif" {
            if block.take().is_none() {
                return Err(format!("module `{name}`: `#endif` without `#if`"));
            }
            continue;
        }
        if block.is_none_or(|(_, on)| on) {
            out.push_str(line);
            out.push('\n');
        }
    }
    match block {
        Some((open, _)) => Err(format!("module `{name}`: `#if {open}` is never closed")),
        None => Ok(out),
    }
}

/// The composed source of module `root` with every feature on: its imports (transitively,
/// each once, dependencies first), then the module itself.
pub fn compose(root: &str) -> Result<String, String> {
    compose_with(root, &|_| true)
}

/// The composed source of module `root` with the `#if` blocks of features for which
/// `enabled` is false left out (their imports too).
pub fn compose_with(root: &str, enabled: &dyn Fn(&str) -> bool) -> Result<String, String> {
    fn visit<'a>(
        name: &'a str,
        enabled: &dyn Fn(&str) -> bool,
        chain: &mut Vec<String>,
        done: &mut Vec<String>,
        out: &mut String,
    ) -> Result<(), String> {
        if done.iter().any(|d| d == name) {
            return Ok(());
        }
        if chain.iter().any(|c| c == name) {
            return Err(format!("import cycle: {} -> {name}", chain.join(" -> ")));
        }
        let (name, source) = MODULES.iter().find(|(n, _)| *n == name).ok_or_else(|| {
            format!(
                "unknown module `{name}` (imported by `{}`)",
                chain.last().map_or("?", |c| c.as_str())
            )
        })?;
        let source = preprocess(name, source, enabled)?;
        chain.push(name.to_string());
        for dep in imports(&source) {
            visit(dep, enabled, chain, done, out)?;
        }
        chain.pop();
        out.push_str(&format!("// ---- module {name} ----\n{source}\n"));
        done.push(name.to_string());
        Ok(())
    }
    let mut out = String::new();
    visit(root, enabled, &mut Vec::new(), &mut Vec::new(), &mut out)?;
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
