//! PCD v0.7 point clouds (Point Cloud Library): `DATA ascii`, `binary` and `binary_compressed`,
//! any fields, sizes, types and counts.
//!
//! The decoded cloud's layout is the file's: fields packed in header order, little-endian. Writing
//! a cloud back produces the same header fields and the same data encoding, so a perturbed PCD is
//! read by the same tools as the original.

use crate::cloud::{Cloud, CloudView, Datatype, PointField, PointLayout};
use crate::error::{Error, Result};
use std::sync::Arc;

/// How the point data of a PCD file is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PcdData {
    /// Whitespace-separated text, one point per line.
    Ascii,
    /// Raw little-endian records.
    Binary,
    /// Field-major records compressed with LZF.
    BinaryCompressed,
}

/// A decoded PCD file: the cloud and how its data was stored.
#[derive(Clone, Debug, PartialEq)]
pub struct PcdFile {
    /// The points.
    pub cloud: Cloud,
    /// The data encoding of the file.
    pub data: PcdData,
    /// The VIEWPOINT line's seven numbers.
    pub viewpoint: [f64; 7],
    /// What was odd but not wrong enough to refuse the file (bytes ignored after the data).
    pub warnings: Vec<String>,
}

fn bad(reason: impl Into<String>) -> Error {
    Error::malformed("PCD", reason)
}

/// Decodes a PCD file.
pub fn decode(bytes: &[u8]) -> Result<PcdFile> {
    let mut pos = 0usize;
    let mut names: Vec<String> = Vec::new();
    let mut sizes: Vec<usize> = Vec::new();
    let mut types: Vec<char> = Vec::new();
    let mut counts: Vec<u32> = Vec::new();
    let (mut width, mut height, mut points) = (None, None, None);
    let mut viewpoint = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
    let data_kind;
    let mut line_no = 0;
    loop {
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
        pos = (end + 1).min(bytes.len());
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
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
        match key.as_str() {
            "VERSION" => {}
            "FIELDS" | "COLUMNS" => names = rest.iter().map(|s| s.to_string()).collect(),
            "SIZE" => sizes = rest.iter().map(|v| num("SIZE", v)).collect::<Result<_>>()?,
            "TYPE" => {
                types = rest
                    .iter()
                    .map(|v| {
                        v.chars()
                            .next()
                            .map(|c| c.to_ascii_uppercase())
                            .filter(|c| matches!(c, 'F' | 'I' | 'U'))
                            .ok_or_else(|| {
                                bad(format!("line {line_no}: TYPE `{v}` is not F, I or U"))
                            })
                    })
                    .collect::<Result<_>>()?
            }
            "COUNT" => {
                counts = rest
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
            "WIDTH" => width = Some(num("WIDTH", rest.first().copied().unwrap_or(""))?),
            "HEIGHT" => height = Some(num("HEIGHT", rest.first().copied().unwrap_or(""))?),
            "POINTS" => points = Some(num("POINTS", rest.first().copied().unwrap_or(""))?),
            "VIEWPOINT" => {
                for (slot, v) in viewpoint.iter_mut().zip(&rest) {
                    *slot = v
                        .parse()
                        .map_err(|_| bad(format!("line {line_no}: VIEWPOINT value `{v}`")))?;
                }
            }
            "DATA" => {
                data_kind = match rest.first().map(|s| s.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => PcdData::Ascii,
                    Some("binary") => PcdData::Binary,
                    Some("binary_compressed") => PcdData::BinaryCompressed,
                    other => {
                        return Err(bad(format!("line {line_no}: unknown DATA kind {other:?}")));
                    }
                };
                break;
            }
            other => return Err(bad(format!("line {line_no}: unknown header key `{other}`"))),
        }
    }
    if names.is_empty() {
        return Err(bad("no FIELDS line"));
    }
    if counts.is_empty() {
        counts = vec![1; names.len()];
    }
    if sizes.len() != names.len() || types.len() != names.len() || counts.len() != names.len() {
        return Err(bad(format!(
            "FIELDS has {} entries but SIZE has {}, TYPE {} and COUNT {}",
            names.len(),
            sizes.len(),
            types.len(),
            counts.len()
        )));
    }
    let mut fields = Vec::with_capacity(names.len());
    let mut offset = 0u32;
    for i in 0..names.len() {
        let dt = Datatype::from_pcd(types[i], sizes[i]).ok_or_else(|| {
            bad(format!(
                "field `{}` has TYPE {} with SIZE {}, which is not a PointCloud2 datatype",
                names[i], types[i], sizes[i]
            ))
        })?;
        fields.push(PointField {
            name: names[i].clone(),
            offset,
            datatype: dt,
            count: counts[i],
        });
        offset = (sizes[i] as u32)
            .checked_mul(counts[i].max(1))
            .and_then(|b| offset.checked_add(b))
            .ok_or_else(|| bad("the fields' SIZE x COUNT add up to more than 4 GiB per point"))?;
    }
    let layout = Arc::new(PointLayout::new(fields, offset, false)?);
    let width = width.ok_or_else(|| bad("no WIDTH line"))?;
    let height = height.unwrap_or(1);
    let area = width
        .checked_mul(height)
        .ok_or_else(|| bad(format!("WIDTH {width} x HEIGHT {height} overflows")))?;
    let n = points.unwrap_or(area);
    if n != area {
        return Err(bad(format!(
            "POINTS {n} is not WIDTH {width} x HEIGHT {height}"
        )));
    }
    let step = layout.point_step as usize;
    let body = &bytes[pos..];
    // Every point is checked against the bytes that follow before its buffer is allocated: a
    // header may announce any size, the data decides.
    n.checked_mul(step)
        .filter(|b| u32::try_from(*b).is_ok())
        .ok_or_else(|| bad(format!("{n} points of {step} bytes exceed 4 GiB")))?;
    let mut warnings = Vec::new();
    let data = match data_kind {
        PcdData::Binary => {
            let need = n * step;
            if body.len() < need {
                return Err(bad(format!(
                    "binary data holds {} bytes but {n} points of {step} bytes need {need} (truncated?)",
                    body.len()
                )));
            }
            trailing(body.len() - need, step, n, &mut warnings)?;
            body[..need].to_vec()
        }
        PcdData::Ascii => decode_ascii(body, &layout, n)?,
        PcdData::BinaryCompressed => {
            let (data, used) = decode_compressed(body, &layout, n)?;
            if body.len() > used {
                warnings.push(format!(
                    "{} bytes after the compressed data were ignored",
                    body.len() - used
                ));
            }
            data
        }
    };
    let dense = dense_xyz(&layout, &data);
    let cloud = Cloud::from_vec(
        layout,
        data,
        width as u32,
        height as u32,
        width * step,
        dense,
    )?;
    Ok(PcdFile {
        cloud,
        data: data_kind,
        viewpoint,
        warnings,
    })
}

/// Bytes after the announced points: whole points mean the header announces fewer points than
/// the data holds (an error: reading only the first ones would silently drop the rest); less than
/// a point is padding, ignored with a warning.
fn trailing(extra: usize, step: usize, n: usize, warnings: &mut Vec<String>) -> Result<()> {
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

fn dense_xyz(layout: &PointLayout, data: &[u8]) -> bool {
    let Ok(readers) = layout.xyz_readers() else {
        return true;
    };
    let step = layout.point_step as usize;
    step == 0
        || data
            .chunks_exact(step)
            .all(|p| readers.iter().all(|r| r.read_f64(p).is_finite()))
}

fn decode_ascii(body: &[u8], layout: &PointLayout, n: usize) -> Result<Vec<u8>> {
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
                let r = crate::cloud::FieldReader {
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
fn decode_compressed(body: &[u8], layout: &PointLayout, n: usize) -> Result<(Vec<u8>, usize)> {
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

/// The most an LZF stream can expand: a 3-byte back reference copies at most 264 bytes.
const LZF_MAX_RATIO: usize = 88;

/// Decompresses an LZF stream (liblzf format) of known output size.
pub fn lzf_decompress(input: &[u8], out_len: usize) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(out_len.min(input.len().saturating_mul(LZF_MAX_RATIO)));
    let mut i = 0;
    while i < input.len() {
        let ctrl = input[i] as usize;
        i += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            if i + len > input.len() || out.len() + len > out_len {
                return Err(bad(format!("LZF literal run at byte {} overflows", i - 1)));
            }
            out.extend_from_slice(&input[i..i + len]);
            i += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *input
                    .get(i)
                    .ok_or_else(|| bad("LZF stream ends inside a back reference"))?
                    as usize;
                i += 1;
            }
            let low = *input
                .get(i)
                .ok_or_else(|| bad("LZF stream ends inside a back reference"))?
                as usize;
            i += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            let len = len + 2;
            if back > out.len() || out.len() + len > out_len {
                return Err(bad(format!(
                    "LZF back reference at byte {} points outside the data",
                    i - 2
                )));
            }
            let start = out.len() - back;
            for k in 0..len {
                out.push(out[start + k]);
            }
        }
    }
    if out.len() != out_len {
        return Err(bad(format!(
            "LZF data decompresses to {} bytes, expected {out_len}",
            out.len()
        )));
    }
    Ok(out)
}

/// Compresses with LZF: a simple greedy matcher over a hash of 3-byte prefixes.
pub fn lzf_compress(input: &[u8]) -> Vec<u8> {
    const HSIZE: usize = 1 << 14;
    let mut table = vec![usize::MAX; HSIZE];
    let mut out = Vec::with_capacity(input.len() + input.len() / 32 + 8);
    let mut lit: Vec<u8> = Vec::with_capacity(32);
    let flush = |out: &mut Vec<u8>, lit: &mut Vec<u8>| {
        for chunk in lit.chunks(32) {
            out.push((chunk.len() - 1) as u8);
            out.extend_from_slice(chunk);
        }
        lit.clear();
    };
    let mut i = 0;
    while i < input.len() {
        if i + 2 < input.len() {
            let h =
                ((input[i] as usize) << 16 | (input[i + 1] as usize) << 8 | input[i + 2] as usize)
                    .wrapping_mul(2_654_435_761)
                    >> 8
                    & (HSIZE - 1);
            let cand = table[h];
            table[h] = i;
            if cand != usize::MAX && i - cand <= 8192 && input[cand..cand + 3] == input[i..i + 3] {
                let max = (input.len() - i).min(264);
                let mut len = 3;
                while len < max && input[cand + len] == input[i + len] {
                    len += 1;
                }
                flush(&mut out, &mut lit);
                let back = i - cand - 1;
                let l = len - 2;
                if l < 7 {
                    out.push(((l << 5) | (back >> 8)) as u8);
                } else {
                    out.push(((7 << 5) | (back >> 8)) as u8);
                    out.push((l - 7) as u8);
                }
                out.push((back & 0xff) as u8);
                i += len;
                continue;
            }
        }
        lit.push(input[i]);
        i += 1;
    }
    flush(&mut out, &mut lit);
    out
}

/// Encodes a cloud as PCD with its own fields (offsets are re-packed in field order; fields are
/// written little-endian).
pub fn encode(cloud: &CloudView<'_>, data: PcdData, viewpoint: [f64; 7]) -> Result<Vec<u8>> {
    let layout = cloud.layout();
    let mut fields: Vec<&PointField> = layout.fields.iter().collect();
    fields.sort_by_key(|f| f.offset);
    let mut header =
        String::from("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS");
    for f in &fields {
        header.push(' ');
        header.push_str(&f.name);
    }
    header.push_str("\nSIZE");
    for f in &fields {
        header.push_str(&format!(" {}", f.datatype.size()));
    }
    header.push_str("\nTYPE");
    for f in &fields {
        header.push_str(&format!(" {}", f.datatype.pcd_type().0));
    }
    header.push_str("\nCOUNT");
    for f in &fields {
        header.push_str(&format!(" {}", f.count.max(1)));
    }
    let vp: Vec<String> = viewpoint.iter().map(|v| v.to_string()).collect();
    header.push_str(&format!(
        "\nWIDTH {}\nHEIGHT {}\nVIEWPOINT {}\nPOINTS {}\nDATA {}\n",
        cloud.width,
        cloud.height,
        vp.join(" "),
        cloud.len(),
        match data {
            PcdData::Ascii => "ascii",
            PcdData::Binary => "binary",
            PcdData::BinaryCompressed => "binary_compressed",
        }
    ));
    let mut out = header.into_bytes();
    let readers: Vec<(crate::cloud::FieldReader, usize)> = fields
        .iter()
        .map(|f| {
            (
                crate::cloud::FieldReader::new(f, layout.big_endian),
                f.count.max(1) as usize,
            )
        })
        .collect();
    // Packed little-endian records.
    let packed_step: usize = fields.iter().map(|f| f.byte_len()).sum();
    let mut packed = Vec::with_capacity(cloud.len() * packed_step);
    for i in 0..cloud.len() {
        let p = cloud.point(i);
        for (f, (r, count)) in fields.iter().zip(&readers) {
            for k in 0..*count {
                let mut r = *r;
                r.offset += k * f.datatype.size();
                let src = &p[r.offset..r.offset + f.datatype.size()];
                if layout.big_endian {
                    packed.extend(src.iter().rev());
                } else {
                    packed.extend_from_slice(src);
                }
            }
        }
    }
    match data {
        PcdData::Binary => out.extend_from_slice(&packed),
        PcdData::Ascii => {
            let le = PointLayout::new(
                {
                    let mut off = 0;
                    fields
                        .iter()
                        .map(|f| {
                            let nf = PointField {
                                offset: off,
                                ..(*f).clone()
                            };
                            off += f.byte_len() as u32;
                            nf
                        })
                        .collect()
                },
                packed_step as u32,
                false,
            )?;
            let mut text = String::with_capacity(cloud.len() * 32);
            for p in packed.chunks_exact(packed_step.max(1)) {
                let mut first = true;
                for f in &le.fields {
                    for k in 0..f.count.max(1) as usize {
                        let r = crate::cloud::FieldReader {
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
            out.extend_from_slice(text.as_bytes());
        }
        PcdData::BinaryCompressed => {
            let n = cloud.len();
            let mut soa = Vec::with_capacity(packed.len());
            let mut off = 0;
            for f in &fields {
                let len = f.byte_len();
                for i in 0..n {
                    let s = i * packed_step + off;
                    soa.extend_from_slice(&packed[s..s + len]);
                }
                off += len;
            }
            let comp = lzf_compress(&soa);
            out.extend_from_slice(&(comp.len() as u32).to_le_bytes());
            out.extend_from_slice(&(soa.len() as u32).to_le_bytes());
            out.extend_from_slice(&comp);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Cloud {
        let layout = PointLayout::new(
            vec![
                PointField::new("x", 0, Datatype::Float32),
                PointField::new("y", 4, Datatype::Float32),
                PointField::new("z", 8, Datatype::Float32),
                PointField::new("intensity", 12, Datatype::Uint8),
                PointField::new("ring", 13, Datatype::Uint16),
                PointField::new("t", 15, Datatype::Float64),
            ],
            23,
            false,
        )
        .unwrap();
        let pts: Vec<[f32; 4]> = (0..300)
            .map(|i| [i as f32 * 0.5, -(i as f32), 1.25, (i % 200) as f32])
            .collect();
        let mut c = Cloud::from_xyzi(&layout, &pts);
        let t = layout.reader("t").unwrap();
        for (i, p) in c.data.chunks_exact_mut(23).enumerate() {
            t.write_f64(p, i as f64 * 1e-4);
        }
        c
    }

    #[test]
    fn all_three_encodings_round_trip() {
        let c = sample();
        for kind in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            let bytes = encode(&c.view(), kind, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).unwrap();
            let back = decode(&bytes).unwrap();
            assert_eq!(back.data, kind);
            assert_eq!(back.cloud, c, "{kind:?}");
        }
    }

    #[test]
    fn lzf_round_trip_on_repetitive_and_random_data() {
        let mut data: Vec<u8> = (0..5000).map(|i| (i / 7 % 13) as u8).collect();
        let mut r = crate::rng::Rng::for_setup(1, 2);
        data.extend((0..3000).map(|_| r.next_u32() as u8));
        let c = lzf_compress(&data);
        assert!(c.len() < data.len());
        assert_eq!(lzf_decompress(&c, data.len()).unwrap(), data);
    }

    #[test]
    fn header_lies_and_truncation_are_reported() {
        let c = sample();
        let bytes = encode(
            &c.view(),
            PcdData::Binary,
            [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
        )
        .unwrap();
        let err = decode(&bytes[..bytes.len() - 5]).unwrap_err();
        assert!(err.to_string().contains("truncated"), "{err}");
        let text = String::from_utf8_lossy(&bytes[..200]).replace("POINTS 300", "POINTS 301");
        let mut lie = text.into_bytes();
        lie.extend_from_slice(&bytes[200..]);
        let err = decode(&lie).unwrap_err();
        assert!(err.to_string().contains("POINTS 301"), "{err}");
        let err = decode(b"VERSION 0.7\nFIELDS x y\nSIZE 4\nTYPE F F\nWIDTH 1\nDATA ascii\n1 2\n")
            .unwrap_err();
        assert!(err.to_string().contains("SIZE has 1"), "{err}");
        assert!(decode(b"VERSION 0.7\n").is_err());
    }

    /// Sizes a header announces are checked against the data before anything is allocated.
    #[test]
    fn huge_announced_sizes_are_refused_before_allocating() {
        let head = |count: &str, width: &str, kind: &str| {
            format!(
                "FIELDS x\nSIZE 4\nTYPE F\nCOUNT {count}\nWIDTH {width}\nHEIGHT 1\nDATA {kind}\n"
            )
            .into_bytes()
        };
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (head("1", "900000000", "ascii"), "more than the"),
            (head("4294967296", "1", "ascii"), "COUNT"),
            (head("4294967295", "2", "ascii"), "4 GiB"),
            (head("1", "18446744073709551615", "ascii"), "exceed"),
            (
                {
                    let mut b = head("1", "100000000", "binary_compressed");
                    b.extend_from_slice(&4u32.to_le_bytes());
                    b.extend_from_slice(&400_000_000u32.to_le_bytes());
                    b.extend_from_slice(&[0, 0, 0, 0]);
                    b
                },
                "more than LZF",
            ),
        ];
        for (bytes, want) in cases {
            let err = decode(&bytes).unwrap_err();
            assert!(err.to_string().contains(want), "{want}: {err}");
        }
        let mut wide =
            b"FIELDS x\nSIZE 4\nTYPE F\nWIDTH 4294967296\nHEIGHT 4294967296\nDATA ascii\n".to_vec();
        wide.extend_from_slice(b"1\n");
        assert!(decode(&wide).unwrap_err().to_string().contains("overflows"));
    }

    /// The header of `bytes` with `WIDTH`/`POINTS` changed from 300 to `n`.
    fn announce(bytes: &[u8], n: usize) -> Vec<u8> {
        let end = bytes.windows(5).position(|w| w == b"DATA ").unwrap();
        let end = end + bytes[end..].iter().position(|b| *b == b'\n').unwrap() + 1;
        let head = String::from_utf8_lossy(&bytes[..end])
            .replace("WIDTH 300", &format!("WIDTH {n}"))
            .replace("POINTS 300", &format!("POINTS {n}"));
        let mut out = head.into_bytes();
        out.extend_from_slice(&bytes[end..]);
        out
    }

    #[test]
    fn more_data_than_the_header_announces_is_not_read_silently() {
        let c = sample();
        let vp = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
        // Binary: 300 points of data under a header announcing 290 is an error naming the count.
        let bin = encode(&c.view(), PcdData::Binary, vp).unwrap();
        let err = decode(&announce(&bin, 290)).unwrap_err().to_string();
        assert!(
            err.contains("announces 290 points") && err.contains("10 more whole points"),
            "{err}"
        );
        // Less than a point of padding is read, with a warning saying how much was ignored.
        let mut padded = bin.clone();
        padded.extend_from_slice(&[0u8; 5]);
        let f = decode(&padded).unwrap();
        assert_eq!(f.cloud, c);
        assert_eq!(f.warnings.len(), 1);
        assert!(f.warnings[0].contains("5 bytes"), "{:?}", f.warnings);
        assert!(decode(&bin).unwrap().warnings.is_empty());
        // Ascii: extra lines are an error too.
        let txt = encode(&c.view(), PcdData::Ascii, vp).unwrap();
        let err = decode(&announce(&txt, 298)).unwrap_err().to_string();
        assert!(err.contains("2 more lines"), "{err}");
        // Compressed: bytes after the compressed block are reported.
        let mut z = encode(&c.view(), PcdData::BinaryCompressed, vp).unwrap();
        z.extend_from_slice(b"junk");
        let f = decode(&z).unwrap();
        assert_eq!(f.cloud, c);
        assert!(f.warnings[0].contains("4 bytes"), "{:?}", f.warnings);
    }
}
