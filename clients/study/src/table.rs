//! Plain tables rendered as aligned text, markdown or CSV.

use crate::Format;

/// A table of strings.
#[derive(Clone, Debug, Default)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows, each as long as the header.
    pub rows: Vec<Vec<String>>,
    /// Columns aligned right in text and markdown (numbers).
    pub right: Vec<bool>,
}

impl Table {
    /// A table with these columns; `right` marks numeric columns.
    pub fn new(header: &[(&str, bool)]) -> Table {
        Table {
            header: header.iter().map(|(h, _)| h.to_string()).collect(),
            rows: Vec::new(),
            right: header.iter().map(|(_, r)| *r).collect(),
        }
    }

    /// Adds a row.
    pub fn push(&mut self, row: Vec<String>) {
        debug_assert_eq!(row.len(), self.header.len());
        self.rows.push(row);
    }

    /// The table as text, markdown or CSV (JSON is the caller's: it has the typed rows).
    pub fn render(&self, format: Format) -> String {
        match format {
            Format::Csv => {
                let mut s = String::new();
                for row in std::iter::once(&self.header).chain(&self.rows) {
                    let cells: Vec<String> = row.iter().map(|c| csv_cell(c)).collect();
                    s.push_str(&cells.join(","));
                    s.push('\n');
                }
                s
            }
            Format::Markdown => {
                let mut s = format!("| {} |\n|", self.header.join(" | "));
                for r in &self.right {
                    s.push_str(if *r { "---:|" } else { "---|" });
                }
                s.push('\n');
                for row in &self.rows {
                    s.push_str(&format!("| {} |\n", row.join(" | ")));
                }
                s
            }
            Format::Table | Format::Json => {
                let w: Vec<usize> = (0..self.header.len())
                    .map(|c| {
                        std::iter::once(&self.header)
                            .chain(&self.rows)
                            .map(|r| r[c].chars().count())
                            .max()
                            .unwrap_or(0)
                    })
                    .collect();
                let mut s = String::new();
                for row in std::iter::once(&self.header).chain(&self.rows) {
                    let cells: Vec<String> = row
                        .iter()
                        .enumerate()
                        .map(|(c, v)| {
                            let pad = " ".repeat(w[c] - v.chars().count());
                            if self.right[c] {
                                format!("{pad}{v}")
                            } else {
                                format!("{v}{pad}")
                            }
                        })
                        .collect();
                    s.push_str(cells.join("  ").trim_end());
                    s.push('\n');
                }
                s
            }
        }
    }
}

fn csv_cell(c: &str) -> String {
    if c.contains([',', '"', '\n']) {
        format!("\"{}\"", c.replace('"', "\"\""))
    } else {
        c.to_string()
    }
}

/// A number with `digits` decimals, or `-` when absent.
pub fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

/// A number for CSV: full precision, or empty when absent.
pub fn raw(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}
