//! The study's figures as SVG, drawn with the `plotters` crate: the trajectory map with failure
//! hotspots ([`map`]) and the report's charts ([`charts`]: latency against the budget, offline
//! metrics per severity, transfer scatter plots, trend and completion bars). SVG text is left to
//! the viewer's fonts, so nothing here needs a font file or a system library, and an SVG is
//! self-contained (inline in the HTML report, or a `.svg` file).

pub mod charts;
mod labels;
pub mod map;

pub use labels::{LabelPlacer, Rect};
pub use map::{MapOptions, trajectory_map};

use crate::error::StudyError;
use plotters::style::RGBColor;

/// Colours of perturbation families, in order of first appearance (the Okabe-Ito palette for
/// colour-blind readers first, then darker tones), never grey (grey is nominal).
pub const PALETTE: [RGBColor; 12] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(120, 94, 240),
    RGBColor(140, 86, 75),
    RGBColor(0, 0, 0),
    RGBColor(188, 150, 34),
    RGBColor(23, 120, 120),
    RGBColor(170, 40, 80),
];

/// Nominal driving.
pub const NOMINAL: RGBColor = RGBColor(128, 128, 128);
/// Ok outcomes (completion bars).
pub const OK_GREEN: RGBColor = RGBColor(40, 150, 60);
/// Failed outcomes.
pub const FAIL_RED: RGBColor = RGBColor(200, 40, 40);
/// Unjudged outcomes.
pub const UNJUDGED_GREY: RGBColor = RGBColor(170, 170, 170);

/// The colour of the k-th series.
pub fn series_colour(k: usize) -> RGBColor {
    PALETTE[k % PALETTE.len()]
}

/// A `plotters` drawing error as the study's error, naming the chart.
pub(crate) fn plot_err<E: std::fmt::Debug>(what: &str) -> impl FnOnce(E) -> StudyError + '_ {
    move |e| StudyError::Plot {
        what: what.to_string(),
        reason: format!("{e:?}"),
    }
}

/// A round length for a scale bar or an axis step: 1, 2 or 5 times a power of ten, at most
/// `max`.
pub fn nice_length(max: f64) -> f64 {
    if !(max.is_finite() && max > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(max.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&v| v <= max)
        .unwrap_or(p)
}

/// `text` escaped for XML (element content and attribute values).
pub fn xml_escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '&' => s.push_str("&amp;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            c => s.push(c),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_lengths_are_one_two_or_five_times_a_power_of_ten() {
        assert_eq!(nice_length(73.0), 50.0);
        assert_eq!(nice_length(20.0), 20.0);
        assert_eq!(nice_length(1.7), 1.0);
        assert_eq!(nice_length(0.31), 0.2);
        assert_eq!(xml_escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }
}
