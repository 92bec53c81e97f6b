//! A small WGSL composer: kernels name the modules they need with `// #import NAME` lines and
//! get one source with every module once, dependencies first. All modules are compiled into
//! the binary from `shaders/`, so no algorithm is written twice in WGSL.
//!
//! Lines between `// #if FEATURE` and `// #endif` (not nested) are kept only when the
//! feature is on, imports included: a scene without meshes gets no mesh code, one without
//! a torus no torus crossing search ([`compose_with`]).
//!
//! A line `// #chunked ARRAY TYPE GROUP BINDING MORE ACCESSOR` declares a read-only storage
//! array that may exceed the device's binding limit, read only through `ACCESSOR(i) ->
//! TYPE`. Without the feature `chunked_ARRAY` it becomes the one binding `@group(GROUP)
//! @binding(BINDING) ARRAY` and an accessor that indexes it; with it, `ARRAY` holds the
//! first `ARRAY_CHUNK_LEN` elements and `ARRAY_1` .. `ARRAY_3` at bindings `MORE`,
//! `MORE + 1`, `MORE + 2` the next ones, as many each (an `override` constant the host
//! sets when it builds the pipeline: [`chunk_constant`]).

/// A WGSL module that cannot be composed (unknown module, import cycle, malformed
/// directive), in words naming the module.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ComposeError(String);

/// Buffers a chunked array is split into (`#chunked`).
pub const CHUNKS: usize = 4;

/// The `override` constant holding a chunked `array`'s elements per chunk.
pub fn chunk_constant(array: &str) -> String {
    format!("{}_CHUNK_LEN", array.to_uppercase())
}

/// The `constants` that composed `source` declares as `override`s: those of arrays whose
/// code the kernel left out (a split mesh array in a kernel without mesh code) are dropped,
/// since a pipeline may set only the constants its module has.
pub fn declared_constants(source: &str, constants: &[(String, f64)]) -> Vec<(String, f64)> {
    (constants.iter())
        .filter(|(name, _)| source.contains(&format!("override {name}:")))
        .cloned()
        .collect()
}

/// A `#chunked` declaration: the array, its element type, its group and first binding, the
/// binding of its second chunk, and its accessor (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkedArray<'a> {
    /// The array's name.
    pub array: &'a str,
    /// The WGSL type of its elements.
    pub ty: &'a str,
    /// Its bind group.
    pub group: u32,
    /// The binding of its only, or first, buffer.
    pub binding: u32,
    /// The binding of its second chunk (the third and fourth follow).
    pub more: u32,
    /// The function that reads element `i`.
    pub accessor: &'a str,
}

impl<'a> ChunkedArray<'a> {
    /// Parses a `#chunked` line's fields; an error names what is malformed.
    fn parse(fields: &'a str) -> Result<ChunkedArray<'a>, ComposeError> {
        let f: Vec<&str> = fields.split_whitespace().collect();
        let [array, ty, group, binding, more, accessor] = f[..] else {
            return Err(ComposeError(format!(
                "`#chunked {fields}`: expected ARRAY TYPE GROUP BINDING MORE ACCESSOR"
            )));
        };
        let number = |v: &str| {
            v.parse::<u32>().map_err(|_| {
                ComposeError(format!(
                    "`#chunked {fields}`: `{v}` is not a binding number"
                ))
            })
        };
        Ok(ChunkedArray {
            array,
            ty,
            group: number(group)?,
            binding: number(binding)?,
            more: number(more)?,
            accessor,
        })
    }

    /// The declaration of `array`, wherever a module of [`MODULES`] writes it: the bindings
    /// the host uploads its buffers to.
    pub fn declared(array: &str) -> Option<ChunkedArray<'static>> {
        MODULES
            .iter()
            .flat_map(|(_, source)| source.lines())
            .filter_map(|l| l.trim().strip_prefix("// #chunked "))
            .filter_map(|fields| ChunkedArray::parse(fields).ok())
            .find(|c| c.array == array)
    }

    /// The bindings of its buffers: its own binding, then those of the chunks after the
    /// first when it is split in `chunks` buffers.
    pub fn bindings(&self, chunks: usize) -> impl Iterator<Item = u32> + '_ {
        std::iter::once(self.binding).chain((1..chunks as u32).map(|c| self.more + c - 1))
    }

    /// Its WGSL: the declarations and the accessor, split when `split`.
    fn wgsl(&self, split: bool) -> String {
        let ChunkedArray {
            array,
            ty,
            group,
            binding,
            accessor,
            ..
        } = *self;
        let declare = |name: &str, binding: u32| {
            format!("@group({group}) @binding({binding}) var<storage, read> {name}: array<{ty}>;\n")
        };
        let mut out = declare(array, binding);
        if !split {
            out.push_str(&format!(
                "fn {accessor}(i: u32) -> {ty} {{\n    return {array}[i];\n}}\n"
            ));
            return out;
        }
        let len = chunk_constant(array);
        out.push_str(&format!("override {len}: u32;\n"));
        let mut cases = String::new();
        for (c, binding) in self.bindings(CHUNKS).enumerate().skip(1) {
            out.push_str(&declare(&format!("{array}_{c}"), binding));
            cases.push_str(&format!(
                "        case {c}u: {{\n            return {array}_{c}[j];\n        }}\n"
            ));
        }
        out.push_str(&format!(
            "fn {accessor}(i: u32) -> {ty} {{\n    let chunk = i / {len};\n    \
             let j = i - chunk * {len};\n    switch chunk {{\n{cases}        default: {{}}\n    }}\n    \
             return {array}[j];\n}}\n"
        ));
        out
    }
}

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
fn preprocess(
    name: &str,
    source: &str,
    enabled: &dyn Fn(&str) -> bool,
) -> Result<String, ComposeError> {
    let mut out = String::with_capacity(source.len());
    let mut block: Option<(&str, bool)> = None;
    for line in source.lines() {
        let trimmed = line.trim();
        if let Some(feature) = trimmed.strip_prefix("// #if ") {
            if let Some((open, _)) = block {
                return Err(ComposeError(format!(
                    "module `{name}`: `#if {feature}` inside `#if {open}`"
                )));
            }
            let feature = feature.trim();
            block = Some((feature, enabled(feature)));
            continue;
        }
        if trimmed == "// #endif" {
            if block.take().is_none() {
                return Err(ComposeError(format!(
                    "module `{name}`: `#endif` without `#if`"
                )));
            }
            continue;
        }
        if block.is_none_or(|(_, on)| on) {
            match trimmed.strip_prefix("// #chunked ") {
                Some(fields) => {
                    let c = ChunkedArray::parse(fields)
                        .map_err(|e| ComposeError(format!("module `{name}`: {e}")))?;
                    out.push_str(&c.wgsl(enabled(&format!("chunked_{}", c.array))));
                }
                None => {
                    out.push_str(line);
                    out.push('\n');
                }
            }
        }
    }
    match block {
        Some((open, _)) => Err(ComposeError(format!(
            "module `{name}`: `#if {open}` is never closed"
        ))),
        None => Ok(out),
    }
}

/// The composed source of module `root` with every feature on: its imports (transitively,
/// each once, dependencies first), then the module itself.
pub fn compose(root: &str) -> Result<String, ComposeError> {
    compose_with(root, &|_| true)
}

/// The composed source of module `root` with the `#if` blocks of features for which
/// `enabled` is false left out (their imports too).
pub fn compose_with(root: &str, enabled: &dyn Fn(&str) -> bool) -> Result<String, ComposeError> {
    fn visit<'a>(
        name: &'a str,
        enabled: &dyn Fn(&str) -> bool,
        chain: &mut Vec<String>,
        done: &mut Vec<String>,
        out: &mut String,
    ) -> Result<(), ComposeError> {
        if done.iter().any(|d| d == name) {
            return Ok(());
        }
        if chain.iter().any(|c| c == name) {
            return Err(ComposeError(format!(
                "import cycle: {} -> {name}",
                chain.join(" -> ")
            )));
        }
        let (name, source) = MODULES.iter().find(|(n, _)| *n == name).ok_or_else(|| {
            ComposeError(format!(
                "unknown module `{name}` (imported by `{}`)",
                chain.last().map_or("?", |c| c.as_str())
            ))
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
        let foundry = src.find("// ---- module generated/foundry ----").unwrap();
        let kernel = src
            .find("// ---- module kernels/foundry_probe ----")
            .unwrap();
        assert!(foundry < kernel);
        assert_eq!(
            src.matches("// ---- module generated/foundry ----").count(),
            1
        );
        assert!(compose("no_such_module")
            .unwrap_err()
            .to_string()
            .contains("unknown module"));
    }

    /// With every feature on (every array split, every optional binding present), no
    /// kernel declares two variables at one group and binding: the `#chunked` lines'
    /// extra bindings collide with nothing.
    #[test]
    fn no_kernel_binds_two_variables_at_one_binding() {
        let mut kernels = 0;
        for (name, _) in MODULES.iter().filter(|(n, _)| n.starts_with("kernels/")) {
            let source = compose(name).unwrap();
            let mut seen = std::collections::HashMap::new();
            for line in source.lines().map(str::trim) {
                let Some(rest) = line.strip_prefix("@group(") else {
                    continue;
                };
                let (group, rest) = rest.split_once(") @binding(").unwrap();
                let (binding, variable) = rest.split_once(')').unwrap();
                let key = (group.to_string(), binding.to_string());
                if let Some(other) = seen.insert(key, variable.to_string()) {
                    panic!("{name}: group {group} binding {binding}: {other} and {variable}");
                }
            }
            kernels += 1;
        }
        assert!(kernels >= 5);
    }
}
