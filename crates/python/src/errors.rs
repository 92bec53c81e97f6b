//! Errors as Python exceptions: the classes of `hytrace/_errors.py`, carrying the messages
//! the command line prints after `hytrace: error: `.

use std::error::Error as StdError;
use std::io::ErrorKind;
use std::path::Path;

use hytrace_trace::choice::Named;
use hytrace_trace::photons::PhotonError;
use pyo3::prelude::*;
use pyo3::types::PyType;

/// An error on its way to Python: the name of its class in `hytrace._errors` and its
/// message. Built without the GIL, raised with it ([`Error::into_pyerr`]).
pub struct Error {
    class: &'static str,
    message: String,
}

impl Error {
    /// The Python exception: an instance of class `hytrace._errors.<class>` (falling back
    /// to `RuntimeError` should that module fail to import).
    pub fn into_pyerr(self) -> PyErr {
        Python::attach(|py| {
            let class = py
                .import("hytrace._errors")
                .and_then(|m| m.getattr(self.class))
                .and_then(|c| Ok(c.cast_into::<PyType>()?));
            match class {
                Ok(class) => PyErr::from_type(class, self.message),
                Err(e) => e,
            }
        })
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        e.into_pyerr()
    }
}

/// A library error: `HytraceFileNotFoundError` when a file is missing,
/// `HytraceValueError` for bad photon run input or sources, else `HytraceError`.
pub fn library_error(e: impl Into<hytrace_trace::Error>) -> Error {
    classify(e.into(), false)
}

/// The error of opening `input`, a file the caller named: as [`library_error`], and a
/// `HytraceFileNotFoundError` whenever that file does not exist (the readers of GDML and
/// volume files report it in their own words).
pub fn open_error(input: &Path) -> impl Fn(hytrace_trace::Error) -> Error + '_ {
    |e| classify(e, !input.exists())
}

/// [`library_error`], a missing file whenever `missing`.
fn classify(e: hytrace_trace::Error, missing: bool) -> Error {
    let causes = || std::iter::successors(Some(&e as &dyn StdError), |&c| c.source());
    let missing = missing
        || causes().any(|c| {
            c.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == ErrorKind::NotFound)
        });
    let bad_input = causes().any(|c| {
        matches!(
            c.downcast_ref::<PhotonError>(),
            Some(PhotonError::Input(_) | PhotonError::Source { .. })
        )
    });
    let class = match (missing, bad_input) {
        (true, _) => "HytraceFileNotFoundError",
        (false, true) => "HytraceValueError",
        _ => "HytraceError",
    };
    Error {
        class,
        message: hytrace_trace::error::report(&e),
    }
}

/// A bad argument value: `HytraceValueError`.
pub fn value_error(message: String) -> Error {
    Error {
        class: "HytraceValueError",
        message,
    }
}

/// An argument of the wrong type: `HytraceTypeError`.
pub fn type_error(message: String) -> Error {
    Error {
        class: "HytraceTypeError",
        message,
    }
}

/// The value of option `name` among the command line's choices (the same names), or a
/// `HytraceValueError` listing them.
pub fn choice<T: Named>(name: &str, value: &str) -> Result<T, Error> {
    T::from_name(value).ok_or_else(|| {
        value_error(format!(
            "invalid value '{value}' for '{name}' [possible values: {}]",
            T::names().join(", ")
        ))
    })
}
