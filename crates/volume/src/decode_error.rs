//! The error of decoding the bytes of a volume file.

/// What is wrong with the bytes of a NanoVDB or OpenVDB file (a codec's stream or frame, a
/// header, a tree), in words; the readers add which file, grid and frame it concerns.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub(crate) struct DecodeError(pub(crate) String);
