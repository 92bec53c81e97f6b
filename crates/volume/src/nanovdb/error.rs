//! The error of reading a NanoVDB file.

use std::fmt;

/// A NanoVDB file that cannot be read, or a grid that cannot be sampled: names the file
/// (and the grid, when one is concerned) and says what is wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NanoError {
    file: String,
    message: String,
}

impl NanoError {
    pub(crate) fn new(file: &str, message: impl Into<String>) -> NanoError {
        NanoError {
            file: file.to_string(),
            message: message.into(),
        }
    }

    /// The file (or the name given to [`crate::parse_nanovdb`]).
    pub fn file(&self) -> &str {
        &self.file
    }

    /// What is wrong, without the file name.
    pub fn message(&self) -> &str {
        &self.message
    }
}

impl fmt::Display for NanoError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.file, self.message)
    }
}

impl std::error::Error for NanoError {}
