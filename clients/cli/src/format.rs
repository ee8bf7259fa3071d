//! The one output format of the commands that print tables (`bench`, `metrics`, `analyze`).

/// Output format of a report or table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// An aligned table for the terminal.
    #[default]
    Table,
    /// A markdown table.
    Markdown,
    /// CSV, one row per perturbation and severity.
    Csv,
    /// JSON.
    Json,
}

impl From<Format> for perturb_study::Format {
    fn from(f: Format) -> Self {
        match f {
            Format::Table => perturb_study::Format::Table,
            Format::Markdown => perturb_study::Format::Markdown,
            Format::Csv => perturb_study::Format::Csv,
            Format::Json => perturb_study::Format::Json,
        }
    }
}
