//! Errors of the Foundry store.

use std::path::PathBuf;

/// What went wrong building, validating, saving or loading a Foundry.
#[derive(Debug, thiserror::Error)]
pub enum FoundryError {
    /// A field of one record holds an impossible value.
    #[error("{array}[{record}].{field}: {problem}")]
    Record {
        /// Array name (also the `.npy` file stem).
        array: &'static str,
        /// Index of the offending record.
        record: usize,
        /// Name of the offending field.
        field: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// A whole array is inconsistent with another (e.g. different lengths).
    #[error("{array}: {problem}")]
    Array {
        /// Array name (also the `.npy` file stem).
        array: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A file of a Foundry directory is malformed or inconsistent.
    #[error("{}: {problem}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
    /// An operating-system error on a file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A builder was given input it cannot store.
    #[error("{0}")]
    Build(String),
}

impl FoundryError {
    /// Re-expresses an array-level error as an error of the file `dir/<array>.npy`.
    pub(crate) fn in_directory(self, dir: &std::path::Path) -> FoundryError {
        match self {
            FoundryError::Record {
                array,
                record,
                field,
                problem,
            } => FoundryError::File {
                path: dir.join(format!("{array}.npy")),
                problem: format!("record {record}, field `{field}`: {problem}"),
            },
            FoundryError::Array { array, problem } => FoundryError::File {
                path: dir.join(format!("{array}.npy")),
                problem,
            },
            other => other,
        }
    }
}

/// Result alias of the crate.
pub type Result<T, E = FoundryError> = std::result::Result<T, E>;
