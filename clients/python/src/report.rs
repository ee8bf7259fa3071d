//! `perturb.report(study_dir, output)`: the study report (`perturb report`) from Python, the
//! same code (perturb-study's `report`) and the same page, tables and CSV files.

use super::{detach, perr};
use perturb_study::report::{ReportOptions, write_report};
use perturb_study::transfer::TransferConfig;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Writes the paper's tables and figures for the study folder `study_dir` (the outputs of
/// `perturb metrics`, `perturb bench`, `perturb analyze ... --out`, `perturb analyze compare`)
/// as one self-contained HTML page at `output`, with `<stem>.json` and `<stem>-<table>.csv`
/// beside it. Returns a dict: `html`, `json`, `csv` (list of paths), `present` (section names),
/// `missing` (section name -> why its input is missing), `used` (input files).
#[pyfunction]
#[pyo3(signature = (study_dir, output = PathBuf::from("report.html"), *, title = None, resamples = 10_000, seed = 0))]
pub fn report<'py>(
    py: Python<'py>,
    study_dir: PathBuf,
    output: PathBuf,
    title: Option<String>,
    resamples: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    if resamples == 0 {
        return Err(perr("resamples must be at least 1"));
    }
    let mut opts = ReportOptions {
        transfer: TransferConfig {
            resamples,
            seed,
            ..TransferConfig::default()
        },
        ..ReportOptions::default()
    };
    if let Some(t) = title {
        opts.title = t;
    }
    let w = detach(py, || write_report(&study_dir, &output, &opts)).map_err(perr)?;
    let d = PyDict::new(py);
    d.set_item("html", w.html)?;
    d.set_item("json", w.json)?;
    d.set_item("csv", w.csv)?;
    d.set_item("present", w.present)?;
    let missing = PyDict::new(py);
    for (name, why) in w.missing {
        missing.set_item(name, why)?;
    }
    d.set_item("missing", missing)?;
    d.set_item("used", w.used)?;
    Ok(d)
}
