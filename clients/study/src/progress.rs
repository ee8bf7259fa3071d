//! How long-running study operations report progress and remarks to whoever called them (the
//! command-line tool draws a progress bar and prints the remarks; a library user may ignore them).

/// Receives progress and remarks. Every method has a do-nothing default.
pub trait Progress: Sync {
    /// The total amount of work, in units of [`Progress::inc`], once it is known.
    fn set_length(&self, _total: u64) {}
    /// `n` more units done.
    fn inc(&self, _n: u64) {}
    /// What is being worked on now.
    fn set_message(&self, _message: &str) {}
    /// A remark for the user (a skipped set, a resumed run, the sensor model chosen).
    fn note(&self, _message: &str) {}
    /// The work is finished.
    fn finish(&self) {}
}

/// Progress that goes nowhere.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Progress for Silent {}
