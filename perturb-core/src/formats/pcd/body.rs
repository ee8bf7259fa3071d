//! The point data after the header: reading each encoding into point-major records, and
//! writing records back in each encoding.

use super::lzf::{LZF_MAX_RATIO, lzf_compress, lzf_decompress};
use super::{PcdData, bad};
use crate::cloud::{CloudView, Datatype, FieldReader, PointField, PointLayout};
use crate::error::Result;

/// Bytes after the announced points: whole points mean the header announces fewer points than
/// the data holds (an error: reading only the first ones would silently drop the rest); less than
/// a point is padding, ignored with a warning.
pub(super) fn trailing(
    extra: usize,
    step: usize,
    n: usize,
    warnings: &mut Vec<String>,
) -> Result<()> {
    if extra == 0 {
        return Ok(());
    }
    if step > 0 && extra >= step {
        return Err(bad(format!(
            "the header announces {n} points but the binary data holds {extra} more bytes ({} more whole points of {step} bytes): fix POINTS/WIDTH/HEIGHT, or cut the data",
            extra / step
        )));
    }
    warnings.push(format!(
        "{extra} bytes after the {n} announced points (less than one point) were ignored"
    ));
    Ok(())
}

pub(super) fn dense_xyz(layout: &PointLayout, data: &[u8]) -> bool {
    let Ok(readers) = layout.xyz_readers() else {
        return true;
    };
    let step = layout.point_step as usize;
    step == 0
        || data
            .chunks_exact(step)
            .all(|p| readers.iter().all(|r| r.read_f64(p).is_finite()))
}

pub(super) fn decode_ascii(body: &[u8], layout: &PointLayout, n: usize) -> Result<Vec<u8>> {
    let text = std::str::from_utf8(body).map_err(|_| bad("ascii data is not text"))?;
    let step = layout.point_step as usize;
    // Each value takes at least one character and a separator.
    let values: usize = layout.fields.iter().map(|f| f.count.max(1) as usize).sum();
    if n.saturating_mul(values) > body.len().div_ceil(2) {
        return Err(bad(format!(
            "the header announces {n} points of {values} values, more than the {} bytes of ascii data can hold",
            body.len()
        )));
    }
    let mut out = vec![0u8; n * step];
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    for (i, point) in out.chunks_exact_mut(step.max(1)).enumerate().take(n) {
        let line = lines
            .next()
            .ok_or_else(|| bad(format!("ascii data has {i} points, the header says {n}")))?;
        let mut vals = line.split_whitespace();
        for f in &layout.fields {
            for k in 0..f.count.max(1) as usize {
                let tok = vals
                    .next()
                    .ok_or_else(|| bad(format!("point {i}: too few values on line `{line}`")))?;
                let v: f64 = match tok {
                    "nan" | "NaN" | "-nan" => f64::NAN,
                    t => t
                        .parse()
                        .map_err(|_| bad(format!("point {i}: `{tok}` is not a number")))?,
                };
                let r = FieldReader {
                    offset: f.offset as usize + k * f.datatype.size(),
                    datatype: f.datatype,
                    big_endian: false,
                };
                r.write_f64(point, v);
            }
        }
    }
    let more = lines.count();
    if more > 0 {
        return Err(bad(format!(
            "the header announces {n} points but the ascii data has {more} more lines: fix POINTS/WIDTH/HEIGHT, or cut the data"
        )));
    }
    Ok(out)
}

/// The points and the bytes of `body` used.
pub(super) fn decode_compressed(
    body: &[u8],
    layout: &PointLayout,
    n: usize,
) -> Result<(Vec<u8>, usize)> {
    if body.len() < 8 {
        return Err(bad(
            "binary_compressed data is shorter than its 8-byte size header",
        ));
    }
    let csize = u32::from_le_bytes(body[0..4].try_into().expect("4 bytes")) as usize;
    let usize_ = u32::from_le_bytes(body[4..8].try_into().expect("4 bytes")) as usize;
    let step = layout.point_step as usize;
    if usize_ != n * step {
        return Err(bad(format!(
            "binary_compressed says {usize_} uncompressed bytes but {n} points of {step} bytes are {}",
            n * step
        )));
    }
    if usize_ > csize.saturating_mul(LZF_MAX_RATIO) {
        return Err(bad(format!(
            "binary_compressed says {csize} compressed bytes expand to {usize_}, more than LZF can ({LZF_MAX_RATIO}x)"
        )));
    }
    if body.len() < 8 + csize {
        return Err(bad(format!(
            "binary_compressed says {csize} compressed bytes but only {} follow (truncated?)",
            body.len() - 8
        )));
    }
    let soa = lzf_decompress(&body[8..8 + csize], usize_)?;
    // Field-major to point-major.
    let mut out = vec![0u8; n * step];
    let mut src = 0;
    for f in &layout.fields {
        let len = f.byte_len();
        for i in 0..n {
            let dst = i * step + f.offset as usize;
            out[dst..dst + len].copy_from_slice(&soa[src..src + len]);
            src += len;
        }
    }
    Ok((out, 8 + csize))
}

/// Reads the `n` points of `body` (the bytes after the header) stored as `data` into
/// point-major records of `layout`; oddities that lose nothing go to `warnings`.
pub(super) fn read(
    data: PcdData,
    body: &[u8],
    layout: &PointLayout,
    n: usize,
    warnings: &mut Vec<String>,
) -> Result<Vec<u8>> {
    let step = layout.point_step as usize;
    match data {
        PcdData::Binary => {
            let need = n * step;
            if body.len() < need {
                return Err(bad(format!(
                    "binary data holds {} bytes but {n} points of {step} bytes need {need} (truncated?)",
                    body.len()
                )));
            }
            trailing(body.len() - need, step, n, warnings)?;
            Ok(body[..need].to_vec())
        }
        PcdData::Ascii => decode_ascii(body, layout, n),
        PcdData::BinaryCompressed => {
            let (points, used) = decode_compressed(body, layout, n)?;
            if body.len() > used {
                warnings.push(format!(
                    "{} bytes after the compressed data were ignored",
                    body.len() - used
                ));
            }
            Ok(points)
        }
    }
}

/// The cloud's points as packed little-endian records of `fields` (in that order), and the
/// record size.
pub(super) fn packed_records(cloud: &CloudView<'_>, fields: &[&PointField]) -> (Vec<u8>, usize) {
    let big_endian = cloud.layout().big_endian;
    let step: usize = fields.iter().map(|f| f.byte_len()).sum();
    let mut packed = Vec::with_capacity(cloud.len() * step);
    for i in 0..cloud.len() {
        let p = cloud.point(i);
        for f in fields {
            let size = f.datatype.size();
            for k in 0..f.count.max(1) as usize {
                let start = f.offset as usize + k * size;
                let src = &p[start..start + size];
                if big_endian {
                    packed.extend(src.iter().rev());
                } else {
                    packed.extend_from_slice(src);
                }
            }
        }
    }
    (packed, step)
}

/// Packed records of `fields` (`step` bytes each) as ascii lines: values separated by a space,
/// floats in Rust's shortest round-trip form, integers in decimal.
pub(super) fn ascii_lines(fields: &[&PointField], packed: &[u8], step: usize) -> Result<String> {
    let mut offset = 0;
    let packed_fields = fields
        .iter()
        .map(|f| {
            let field = PointField {
                offset,
                ..(*f).clone()
            };
            offset += f.byte_len() as u32;
            field
        })
        .collect();
    let le = PointLayout::new(packed_fields, step as u32, false)?;
    let mut text = String::with_capacity(packed.len() / step.max(1) * 32);
    for p in packed.chunks_exact(step.max(1)) {
        let mut first = true;
        for f in &le.fields {
            for k in 0..f.count.max(1) as usize {
                let r = FieldReader {
                    offset: f.offset as usize + k * f.datatype.size(),
                    datatype: f.datatype,
                    big_endian: false,
                };
                if !first {
                    text.push(' ');
                }
                first = false;
                match f.datatype {
                    Datatype::Float32 => text.push_str(&r.read_f32(p).to_string()),
                    Datatype::Float64 => text.push_str(&r.read_f64(p).to_string()),
                    _ => text.push_str(&(r.read_f64(p) as i64).to_string()),
                }
            }
        }
        text.push('\n');
    }
    Ok(text)
}

/// Packed records of `fields` (`step` bytes each) as `binary_compressed` data: field-major, LZF
/// compressed, after the compressed and uncompressed sizes (u32 little-endian).
pub(super) fn compressed(fields: &[&PointField], packed: &[u8], step: usize) -> Vec<u8> {
    let n = packed.len() / step.max(1);
    let mut soa = Vec::with_capacity(packed.len());
    let mut off = 0;
    for f in fields {
        let len = f.byte_len();
        for i in 0..n {
            let s = i * step + off;
            soa.extend_from_slice(&packed[s..s + len]);
        }
        off += len;
    }
    let comp = lzf_compress(&soa);
    let mut out = Vec::with_capacity(8 + comp.len());
    out.extend_from_slice(&(comp.len() as u32).to_le_bytes());
    out.extend_from_slice(&(soa.len() as u32).to_le_bytes());
    out.extend_from_slice(&comp);
    out
}
