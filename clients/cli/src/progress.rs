//! The study library's progress and remarks, shown as an indicatif progress bar and lines on
//! stderr.

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar (hidden with `quiet`) that prints the library's remarks above itself.
pub struct Bar(ProgressBar);

impl Bar {
    /// A bar counting `unit` ("frames", "clouds detected", ...), hidden when `quiet`.
    pub fn new(unit: &str, quiet: bool) -> Self {
        if quiet {
            return Bar(ProgressBar::hidden());
        }
        let pb = ProgressBar::new(0);
        pb.set_style(
            ProgressStyle::with_template(&format!(
                "{{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {unit} {{msg}} (eta {{eta}})"
            ))
            .expect("template")
            .progress_chars("=> "),
        );
        Bar(pb)
    }
}

impl perturb_study::Progress for Bar {
    fn set_length(&self, total: u64) {
        self.0.set_length(total)
    }
    fn inc(&self, n: u64) {
        self.0.inc(n)
    }
    fn set_message(&self, message: &str) {
        self.0.set_message(message.to_string())
    }
    fn note(&self, message: &str) {
        self.0.suspend(|| eprintln!("{message}"))
    }
    fn finish(&self) {
        self.0.finish_and_clear()
    }
}

/// Remarks only: printed on stderr.
pub struct Notes;

impl perturb_study::Progress for Notes {
    fn note(&self, message: &str) {
        eprintln!("{message}")
    }
}
