//! The text header of a PCD file: its lines read into a [`Header`], the point layout and the
//! point count derived from them, every size checked before anything is allocated.

use super::{PcdData, bad};
use crate::cloud::{Datatype, PointField, PointLayout};
use crate::error::Result;
use std::sync::Arc;

/// The header lines of a PCD file, as read (nothing checked across lines yet).
pub(super) struct Header {
    names: Vec<String>,
    sizes: Vec<usize>,
    types: Vec<char>,
    counts: Vec<u32>,
    width: Option<usize>,
    height: Option<usize>,
    points: Option<usize>,
    /// The VIEWPOINT line's seven numbers (identity when absent).
    pub viewpoint: [f64; 7],
    /// The DATA line's encoding.
    pub data: PcdData,
    /// Offset of the first byte after the DATA line.
    pub body: usize,
}

impl Header {
    /// Reads the header lines up to and including the DATA line.
    pub fn read(bytes: &[u8]) -> Result<Header> {
        let mut header = Header {
            names: Vec::new(),
            sizes: Vec::new(),
            types: Vec::new(),
            counts: Vec::new(),
            width: None,
            height: None,
            points: None,
            viewpoint: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            data: PcdData::Binary,
            body: 0,
        };
        let mut line_no = 0;
        loop {
            let pos = header.body;
            if pos >= bytes.len() {
                return Err(bad("header ends before the DATA line"));
            }
            let end = bytes[pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(bytes.len(), |e| pos + e);
            let line = std::str::from_utf8(&bytes[pos..end])
                .map_err(|_| bad(format!("header line {} is not text", line_no + 1)))?
                .trim();
            line_no += 1;
            header.body = (end + 1).min(bytes.len());
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            if header.read_line(line, line_no)? {
                return Ok(header);
            }
        }
    }

    /// Reads one header line's values; true at the DATA line, which ends the header.
    fn read_line(&mut self, line: &str, line_no: usize) -> Result<bool> {
        let mut it = line.split_whitespace();
        let key = it.next().unwrap_or_default().to_ascii_uppercase();
        let rest: Vec<&str> = it.collect();
        let num = |what: &str, v: &str| -> Result<usize> {
            v.parse::<usize>().map_err(|_| {
                bad(format!(
                    "line {line_no}: {what} `{v}` is not a non-negative integer"
                ))
            })
        };
        let first = rest.first().copied().unwrap_or("");
        match key.as_str() {
            "VERSION" => {}
            "FIELDS" | "COLUMNS" => self.names = rest.iter().map(|s| s.to_string()).collect(),
            "SIZE" => self.sizes = rest.iter().map(|v| num("SIZE", v)).collect::<Result<_>>()?,
            "TYPE" => {
                self.types = rest
                    .iter()
                    .map(|v| pcd_type(v, line_no))
                    .collect::<Result<_>>()?
            }
            "COUNT" => {
                self.counts = rest
                    .iter()
                    .map(|v| {
                        num("COUNT", v).and_then(|c| {
                            u32::try_from(c).map_err(|_| {
                                bad(format!("line {line_no}: COUNT `{v}` is too large"))
                            })
                        })
                    })
                    .collect::<Result<_>>()?
            }
            "WIDTH" => self.width = Some(num("WIDTH", first)?),
            "HEIGHT" => self.height = Some(num("HEIGHT", first)?),
            "POINTS" => self.points = Some(num("POINTS", first)?),
            "VIEWPOINT" => {
                for (slot, v) in self.viewpoint.iter_mut().zip(&rest) {
                    *slot = v
                        .parse()
                        .map_err(|_| bad(format!("line {line_no}: VIEWPOINT value `{v}`")))?;
                }
            }
            "DATA" => {
                self.data = match first.to_ascii_lowercase().as_str() {
                    "ascii" => PcdData::Ascii,
                    "binary" => PcdData::Binary,
                    "binary_compressed" => PcdData::BinaryCompressed,
                    _ => {
                        let other = rest.first().map(|s| s.to_ascii_lowercase());
                        return Err(bad(format!("line {line_no}: unknown DATA kind {other:?}")));
                    }
                };
                return Ok(true);
            }
            other => return Err(bad(format!("line {line_no}: unknown header key `{other}`"))),
        }
        Ok(false)
    }

    /// The point layout the FIELDS, SIZE, TYPE and COUNT lines describe (COUNT 1 for every field
    /// when absent), fields packed in header order.
    pub fn layout(&self) -> Result<Arc<PointLayout>> {
        let names = &self.names;
        if names.is_empty() {
            return Err(bad("no FIELDS line"));
        }
        let counts = if self.counts.is_empty() {
            vec![1; names.len()]
        } else {
            self.counts.clone()
        };
        if self.sizes.len() != names.len()
            || self.types.len() != names.len()
            || counts.len() != names.len()
        {
            return Err(bad(format!(
                "FIELDS has {} entries but SIZE has {}, TYPE {} and COUNT {}",
                names.len(),
                self.sizes.len(),
                self.types.len(),
                counts.len()
            )));
        }
        let mut fields = Vec::with_capacity(names.len());
        let mut offset = 0u32;
        for (i, name) in names.iter().enumerate() {
            let (ty, size) = (self.types[i], self.sizes[i]);
            let datatype = Datatype::from_pcd(ty, size).ok_or_else(|| {
                bad(format!(
                    "field `{name}` has TYPE {ty} with SIZE {size}, which is not a PointCloud2 datatype"
                ))
            })?;
            fields.push(PointField {
                name: name.clone(),
                offset,
                datatype,
                count: counts[i],
            });
            offset = (size as u32)
                .checked_mul(counts[i].max(1))
                .and_then(|b| offset.checked_add(b))
                .ok_or_else(|| {
                    bad("the fields' SIZE x COUNT add up to more than 4 GiB per point")
                })?;
        }
        Ok(Arc::new(PointLayout::new(fields, offset, false)?))
    }

    /// (width, height, points): WIDTH (required), HEIGHT (1 when absent) and POINTS, which must
    /// be their product.
    pub fn extent(&self) -> Result<(usize, usize, usize)> {
        let width = self.width.ok_or_else(|| bad("no WIDTH line"))?;
        let height = self.height.unwrap_or(1);
        let area = width
            .checked_mul(height)
            .ok_or_else(|| bad(format!("WIDTH {width} x HEIGHT {height} overflows")))?;
        let n = self.points.unwrap_or(area);
        if n != area {
            return Err(bad(format!(
                "POINTS {n} is not WIDTH {width} x HEIGHT {height}"
            )));
        }
        Ok((width, height, n))
    }
}

/// One TYPE value: `F`, `I` or `U` (either case).
fn pcd_type(v: &str, line_no: usize) -> Result<char> {
    v.chars()
        .next()
        .map(|c| c.to_ascii_uppercase())
        .filter(|c| matches!(c, 'F' | 'I' | 'U'))
        .ok_or_else(|| bad(format!("line {line_no}: TYPE `{v}` is not F, I or U")))
}
