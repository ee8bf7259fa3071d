//! Errors of the wire layer: each says what failed and on which service.

use thiserror::Error;

/// Everything that can go wrong between processes.
#[derive(Debug, Error)]
pub enum WireError {
    /// The header's magic or version is not this build's: the peer speaks another wire format.
    #[error(
        "wire format mismatch: frame header has magic {magic:?} version {found}, this build reads version {expected} (rebuild the peer against the same perturb-wire)"
    )]
    VersionMismatch {
        /// The magic found.
        magic: [u8; 4],
        /// The version found.
        found: u16,
        /// The version this build speaks.
        expected: u16,
    },
    /// Header and payload disagree, or the header describes something impossible.
    #[error("invalid frame: {reason}")]
    InvalidFrame {
        /// What is wrong.
        reason: String,
    },
    /// The frame is fine but perturb-core cannot represent it (unsupported encoding, no x/y/z).
    #[error("invalid frame: {0}")]
    Core(#[from] perturb_core::Error),
    /// A string does not fit its fixed-size header field.
    #[error("{what} `{value}` is longer than the {max} bytes the frame header holds")]
    TooLong {
        /// Which field.
        what: &'static str,
        /// The value.
        value: String,
        /// Capacity in bytes.
        max: usize,
    },
    /// The point layout has more fields than the header holds.
    #[error("point layout has {count} fields; the frame header holds at most {max}")]
    TooManyFields {
        /// Fields in the layout.
        count: usize,
        /// Capacity.
        max: usize,
    },
    /// The service exists with another frame header type (another wire version) or other QoS.
    #[error("cannot open iceoryx2 service `{service}`: {detail}")]
    Incompatible {
        /// The service name.
        service: String,
        /// What iceoryx2 reported, with a hint.
        detail: String,
    },
    /// The service does not exist (nobody created it yet).
    #[error("iceoryx2 service `{service}` does not exist: {hint}")]
    NoSuchService {
        /// The service name.
        service: String,
        /// What to check.
        hint: String,
    },
    /// Any other iceoryx2 failure.
    #[error("iceoryx2: {what}: {detail}")]
    Iceoryx {
        /// What was attempted.
        what: String,
        /// The iceoryx2 error.
        detail: String,
    },
    /// The subscriber already holds as many frames as the service's `subscriber_borrowed` allows.
    #[error(
        "subscriber on `{service}` holds the most frames the service allows (subscriber_borrowed); release one first"
    )]
    BorrowLimit {
        /// The service name.
        service: String,
    },
    /// The service is full (too many clients at once) and stayed full while retrying.
    #[error("iceoryx2 service `{service}` is busy: {detail}")]
    Busy {
        /// The service name.
        service: String,
        /// How full, and what to do.
        detail: String,
    },
    /// A configuration value is wrong.
    #[error("{0}")]
    Config(String),
    /// The control peer answered with an error or not at all.
    #[error("{0}")]
    Control(String),
}

/// Result of the wire layer.
pub type WireResult<T> = Result<T, WireError>;

impl WireError {
    /// Shorthand for [`WireError::InvalidFrame`].
    pub fn invalid(reason: impl Into<String>) -> Self {
        WireError::InvalidFrame {
            reason: reason.into(),
        }
    }

    /// Shorthand for [`WireError::Iceoryx`].
    pub fn iox(what: impl Into<String>, e: impl std::fmt::Debug) -> Self {
        WireError::Iceoryx {
            what: what.into(),
            detail: format!("{e:?}"),
        }
    }

    /// True for [`WireError::BorrowLimit`] (not a transport failure).
    pub fn is_borrow_limit(&self) -> bool {
        matches!(self, WireError::BorrowLimit { .. })
    }

    /// True for errors that describe a bad frame (as opposed to a transport failure): the frame is
    /// counted as invalid and skipped.
    pub fn is_invalid_frame(&self) -> bool {
        matches!(
            self,
            WireError::VersionMismatch { .. }
                | WireError::InvalidFrame { .. }
                | WireError::Core(_)
                | WireError::TooManyFields { .. }
                | WireError::TooLong { .. }
        )
    }
}
