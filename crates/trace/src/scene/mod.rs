//! Scenes: the embedded default scene and loading a scene argument.

mod default;

use std::path::Path;

use anyhow::{bail, Context};
use hytrace_foundry::Foundry;

pub use default::default_scene;

/// Loads the scene named on the command line: none or `default` gives the embedded default
/// scene; a directory is read as a Foundry written by `hytrace foundry`.
pub fn load_scene(arg: Option<&Path>) -> anyhow::Result<Foundry> {
    match arg {
        None => default_scene(),
        Some(p) if p.as_os_str() == "default" => default_scene(),
        Some(p) if p.is_dir() => Foundry::load(p).with_context(|| format!("loading Foundry directory {}", p.display())),
        Some(p) if !p.exists() => bail!("{}: no such file or directory", p.display()),
        Some(p) => bail!(
            "{}: not a scene this build reads (expected `default` or a Foundry directory with meta.json)",
            p.display()
        ),
    }
}
