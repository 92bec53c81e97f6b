//! The library's error: every failure of loading a scene, tracing, rendering, sampling a
//! volume or writing an output, as one type the command line (and the Python package)
//! turns into a message.
//!
//! Each variant's message is complete: a wrapped error or a context shows its cause after
//! a colon, and also returns it from `source()`, so that callers can find a cause by type
//! (a missing file, bad photon input) by walking the chain. [`report`] writes an error and
//! its causes once each.

use std::fmt::Display;

use hytrace_csg::wide_bvh::WideBvhError;
use hytrace_csg::{CsgError, ExprError};
use hytrace_foundry::gdml::GdmlError;
use hytrace_foundry::FoundryError;
use hytrace_volume::{NanoError, StoreError, VolumeError};

use crate::gpu::nanovdb::NanoGpuError;
use crate::gpu::{GpuError, StreamError};
use crate::photons::PhotonError;
use crate::render::detector::DetectorError;
use crate::sweep::SweepError;

/// What went wrong in the library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Input the library cannot use (a value out of range, a malformed scene entry, a
    /// missing name), in words that name the input.
    #[error("{0}")]
    Invalid(String),
    /// A failure, with what was being done when it happened (the file, the grid, the step).
    #[error("{context}: {source}")]
    Context {
        /// What was being done.
        context: String,
        /// The failure.
        source: Box<Error>,
    },
    /// A file operation failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// A scene file is not valid TOML or does not have the scene's fields.
    #[error("{0}")]
    Toml(#[from] toml::de::Error),
    /// A PNG image cannot be encoded.
    #[error("{0}")]
    Png(#[from] png::EncodingError),
    /// An OpenEXR image cannot be encoded.
    #[error("{0}")]
    Exr(#[from] exr::error::Error),
    /// A Foundry store cannot be built, validated, written or read.
    #[error("{0}")]
    Foundry(#[from] FoundryError),
    /// A GDML file cannot be read.
    #[error("{0}")]
    Gdml(#[from] GdmlError),
    /// A solid's parameters cannot describe it.
    #[error("{0}")]
    Csg(#[from] CsgError),
    /// A CSG expression cannot be parsed.
    #[error("{0}")]
    Expr(#[from] ExprError),
    /// A BVH cannot be collapsed into eight-wide nodes.
    #[error("{0}")]
    WideBvh(#[from] WideBvhError),
    /// A volume cannot be read, built or sampled.
    #[error("{0}")]
    Volume(#[from] VolumeError),
    /// A NanoVDB file cannot be read.
    #[error("{0}")]
    Nano(#[from] NanoError),
    /// A brick store cannot be written or read.
    #[error("{0}")]
    Store(#[from] StoreError),
    /// The GPU failed or refused the work.
    #[error("{0}")]
    Gpu(#[from] GpuError),
    /// A brick store cannot be streamed through the GPU's brick pool.
    #[error("{0}")]
    Stream(#[from] StreamError),
    /// A detector view cannot be drawn as asked.
    #[error("{0}")]
    Detector(#[from] DetectorError),
    /// A NanoVDB grid was not read on the GPU.
    #[error("{0}")]
    NanoGpu(#[from] NanoGpuError),
    /// Photon propagation cannot run.
    #[error("{0}")]
    Photon(#[from] PhotonError),
    /// A ray sweep is too large.
    #[error("{0}")]
    Sweep(#[from] SweepError),
}

/// Result of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An [`Error::Invalid`] with `message`.
    pub fn invalid(message: impl Display) -> Error {
        Error::Invalid(message.to_string())
    }

    /// The failure under the contexts added to it.
    pub fn without_context(&self) -> &Error {
        match self {
            Error::Context { source, .. } => source.without_context(),
            other => other,
        }
    }

    /// This error after `context`, what was being done when it happened.
    pub fn context(self, context: impl Display) -> Error {
        Error::Context {
            context: context.to_string(),
            source: Box::new(self),
        }
    }
}

/// The message of `e` followed by its causes (`source()`), each cause left out when the
/// message so far already ends with it: the whole story once, however an error shows its
/// causes. What the command line prints after `hytrace: error: `.
pub fn report(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    for cause in std::iter::successors(e.source(), |&c| c.source()) {
        let cause = cause.to_string();
        if !text.ends_with(&cause) {
            text = format!("{text}: {cause}");
        }
    }
    text
}

/// Adds what was being done to the error of a `Result`, or makes the missing value of an
/// `Option` an [`Error::Invalid`] with that text.
pub trait Context<T> {
    /// The error, if any, after `context`.
    fn context(self, context: impl Display) -> Result<T>;

    /// The error, if any, after the context `f` makes.
    fn with_context<C: Display>(self, f: impl FnOnce() -> C) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context(self, context: impl Display) -> Result<T> {
        self.map_err(|e| e.into().context(context))
    }

    fn with_context<C: Display>(self, f: impl FnOnce() -> C) -> Result<T> {
        self.map_err(|e| e.into().context(f()))
    }
}

impl<T> Context<T> for Option<T> {
    fn context(self, context: impl Display) -> Result<T> {
        self.ok_or_else(|| Error::invalid(context))
    }

    fn with_context<C: Display>(self, f: impl FnOnce() -> C) -> Result<T> {
        self.ok_or_else(|| Error::invalid(f()))
    }
}

/// Returns an [`Error::Invalid`] made with `format!` from the function.
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::error::Error::Invalid(format!($($arg)*)))
    };
}

/// Returns an [`Error::Invalid`] made with `format!` from the function unless `cond` holds.
macro_rules! ensure {
    ($cond:expr, $($arg:tt)*) => {
        // A match, not `if !cond`: conditions on floats read as written (NaN fails them).
        match $cond {
            true => {}
            false => $crate::error::bail!($($arg)*),
        }
    };
}

pub(crate) use {bail, ensure};

#[cfg(test)]
mod tests {
    use std::io::{Error as IoError, ErrorKind};

    use super::*;

    #[test]
    fn contexts_show_their_causes_and_a_report_writes_each_once() {
        let e = Error::from(IoError::new(ErrorKind::NotFound, "no such file"))
            .context("scene.toml")
            .context("loading the scene");
        assert_eq!(e.to_string(), "loading the scene: scene.toml: no such file");
        assert_eq!(report(&e), e.to_string());
        // The cause is found by type under the contexts.
        assert!(matches!(e.without_context(), Error::Io(io) if io.kind() == ErrorKind::NotFound));
        let io = std::iter::successors(Some(&e as &dyn std::error::Error), |&c| c.source())
            .find_map(|c| c.downcast_ref::<IoError>());
        assert_eq!(io.map(IoError::kind), Some(ErrorKind::NotFound));

        // An error that leaves its cause out of its message gets it added.
        #[derive(Debug, thiserror::Error)]
        #[error("cannot read")]
        struct Terse(#[source] IoError);
        let terse = Terse(IoError::new(ErrorKind::NotFound, "no such file"));
        assert_eq!(report(&terse), "cannot read: no such file");
    }

    #[test]
    fn options_and_checks_give_invalid_errors() {
        assert_eq!(
            None::<u32>
                .context("no grid `density`")
                .unwrap_err()
                .to_string(),
            "no grid `density`"
        );
        let check = |x: f64| -> Result<()> {
            ensure!(x > 0.0, "x must be > 0, got {x}");
            Ok(())
        };
        assert!(check(1.0).is_ok());
        assert_eq!(
            check(-1.0).unwrap_err().to_string(),
            "x must be > 0, got -1"
        );
        assert!(matches!(check(f64::NAN), Err(Error::Invalid(_))));
    }
}
