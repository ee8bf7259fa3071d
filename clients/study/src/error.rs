//! The study's error type: every variant says what failed and names the file, run, topic or
//! field concerned.

use perturb_bag::BagError;
use perturb_bag::dynamic::DynError;
use std::path::PathBuf;

/// Everything that can go wrong in the study.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// A file or folder could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// An input file or folder is not what the operation needs.
    #[error("{}: {reason}", path.display())]
    Input {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The perturbation library refused something (an unknown ID, a frame it cannot perturb).
    #[error("{context}: {source}")]
    Perturb {
        /// What was being done.
        context: String,
        /// The library's error.
        source: perturb_core::Error,
    },
    /// The perturbation library refused a request that explains itself (an unknown ID, a
    /// severity out of range, an unknown sensor model).
    #[error(transparent)]
    Core(#[from] perturb_core::Error),
    /// A bag could not be read or written.
    #[error(transparent)]
    Bag(#[from] BagError),
    /// An option or a selection is invalid.
    #[error("{0}")]
    Config(String),
    /// A recorded run could not be analysed.
    #[error("run `{run}`: {reason}")]
    Run {
        /// The run's name.
        run: String,
        /// What is wrong.
        reason: String,
    },
    /// A configured topic field could not be read in a run.
    #[error("run `{run}`: topic `{topic}`, field `{field}`: {source}")]
    Field {
        /// The run's name.
        run: String,
        /// The topic.
        topic: String,
        /// The configured field path.
        field: String,
        /// What the decoder found.
        source: Box<DynError>,
    },
    /// A reference route is unusable.
    #[error("route {}: {reason}", path.display())]
    Route {
        /// The route file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A chart could not be drawn.
    #[error("drawing {what}: {reason}")]
    Plot {
        /// The chart.
        what: String,
        /// What the drawing library said.
        reason: String,
    },
    /// A table given as input (CSV or JSON) is unusable.
    #[error("{}{}: {reason}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Table {
        /// The table file.
        path: PathBuf,
        /// The line, when the problem is on one.
        line: Option<usize>,
        /// What is wrong.
        reason: String,
    },
}

/// The study's result type.
pub type Result<T, E = StudyError> = std::result::Result<T, E>;

impl StudyError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> StudyError {
        let path = path.into();
        move |source| StudyError::Io { path, source }
    }

    /// An input problem with `path`.
    pub fn input(path: impl Into<PathBuf>, reason: impl Into<String>) -> StudyError {
        StudyError::Input {
            path: path.into(),
            reason: reason.into(),
        }
    }

    /// A perturbation-library error while doing `context`.
    pub fn perturb(context: impl Into<String>) -> impl FnOnce(perturb_core::Error) -> StudyError {
        let context = context.into();
        move |source| StudyError::Perturb { context, source }
    }
}
