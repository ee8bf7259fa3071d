//! The error type of the core: every variant says what was wrong and where.

use thiserror::Error;

/// Everything that can go wrong in the core, each variant naming what failed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum Error {
    /// The perturbation ID is not in the catalogue.
    #[error("unknown perturbation `{id}` (run `perturb list` for the catalogue)")]
    UnknownPerturbation {
        /// The ID that was asked for.
        id: String,
    },
    /// The severity is outside the perturbation's range.
    #[error("severity {severity} is out of range for {id}: valid severities are 1..={max}")]
    SeverityOutOfRange {
        /// The perturbation ID.
        id: &'static str,
        /// The severity that was asked for.
        severity: u8,
        /// The highest valid severity.
        max: u8,
    },
    /// A camera perturbation was applied to a point cloud or the other way round.
    #[error("{id} is a {expected} perturbation and cannot be applied to a {found}")]
    WrongModality {
        /// The perturbation ID.
        id: &'static str,
        /// The modality the perturbation works on.
        expected: &'static str,
        /// What it was given.
        found: &'static str,
    },
    /// An image buffer does not match the geometry it claims.
    #[error("invalid image: {reason}")]
    InvalidImage {
        /// What is wrong.
        reason: String,
    },
    /// The pixel encoding is not one the project handles (the supported ones are the rows of
    /// [`crate::encoding::ENCODINGS`]).
    #[error(
        "unsupported pixel encoding `{encoding}` (supported: {})",
        crate::encoding::supported()
    )]
    UnsupportedEncoding {
        /// The encoding string as received.
        encoding: String,
    },
    /// A field of an image holds a value its encoding does not allow.
    #[error("invalid {encoding} image: {field} {value} {problem}")]
    ImageField {
        /// The encoding, as the table names it.
        encoding: &'static str,
        /// The field.
        field: crate::encoding::ImageField,
        /// Its value.
        value: u64,
        /// What is wrong with it.
        problem: crate::encoding::FieldProblem,
    },
    /// A perturbation cannot work on this pixel format.
    #[error("{id} does not support pixel format {format}")]
    UnsupportedPixelFormat {
        /// The perturbation ID.
        id: &'static str,
        /// The pixel format.
        format: &'static str,
    },
    /// A point-cloud buffer or layout is inconsistent.
    #[error("invalid point cloud: {reason}")]
    InvalidCloud {
        /// What is wrong.
        reason: String,
    },
    /// A field the operation needs is absent from the point layout.
    #[error("point cloud has no `{field}` field{hint}")]
    MissingField {
        /// The missing field.
        field: &'static str,
        /// Extra guidance, starting with a separator, or empty.
        hint: &'static str,
    },
    /// The output buffer cannot hold the result.
    #[error("output buffer too small: {needed} bytes needed, {available} available")]
    OutputTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes available.
        available: usize,
    },
    /// Input and output geometries differ where they must agree.
    #[error("geometry mismatch: expected {expected}, found {found}")]
    GeometryMismatch {
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
    /// Bytes could not be decoded as the format they claim to be.
    #[error("malformed {format}: {reason}")]
    Malformed {
        /// The format (e.g. "PCD", "KITTI .bin", "sensor_msgs/Image CDR").
        format: &'static str,
        /// What is wrong, with the position where it helps.
        reason: String,
    },
    /// A configuration value is invalid.
    #[error("invalid configuration: {reason}")]
    InvalidConfig {
        /// What is wrong.
        reason: String,
    },
}

/// The core's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Shorthand for [`Error::Malformed`].
    pub fn malformed(format: &'static str, reason: impl Into<String>) -> Self {
        Error::Malformed {
            format,
            reason: reason.into(),
        }
    }

    /// Shorthand for [`Error::InvalidCloud`].
    pub fn cloud(reason: impl Into<String>) -> Self {
        Error::InvalidCloud {
            reason: reason.into(),
        }
    }

    /// Shorthand for [`Error::InvalidImage`].
    pub fn image(reason: impl Into<String>) -> Self {
        Error::InvalidImage {
            reason: reason.into(),
        }
    }
}
