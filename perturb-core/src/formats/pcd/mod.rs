//! PCD v0.7 point clouds (Point Cloud Library): `DATA ascii`, `binary` and `binary_compressed`,
//! any fields, sizes, types and counts.
//!
//! The decoded cloud's layout is the file's: fields packed in header order, little-endian. Writing
//! a cloud back produces the same header fields and the same data encoding, so a perturbed PCD is
//! read by the same tools as the original.

mod body;
mod header;
mod lzf;

pub use lzf::{lzf_compress, lzf_decompress};

use crate::cloud::{Cloud, CloudView, PointField};
use crate::error::{Error, Result};
use header::Header;

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
    let header = Header::read(bytes)?;
    let layout = header.layout()?;
    let (width, height, n) = header.extent()?;
    let step = layout.point_step as usize;
    // Every point is checked against the bytes that follow before its buffer is allocated: a
    // header may announce any size, the data decides.
    n.checked_mul(step)
        .filter(|b| u32::try_from(*b).is_ok())
        .ok_or_else(|| bad(format!("{n} points of {step} bytes exceed 4 GiB")))?;
    let mut warnings = Vec::new();
    let data = body::read(
        header.data,
        &bytes[header.body..],
        &layout,
        n,
        &mut warnings,
    )?;
    let dense = body::dense_xyz(&layout, &data);
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
        data: header.data,
        viewpoint: header.viewpoint,
        warnings,
    })
}

/// Encodes a cloud as PCD with its own fields (offsets are re-packed in field order; fields are
/// written little-endian).
pub fn encode(cloud: &CloudView<'_>, data: PcdData, viewpoint: [f64; 7]) -> Result<Vec<u8>> {
    let mut fields: Vec<&PointField> = cloud.layout().fields.iter().collect();
    fields.sort_by_key(|f| f.offset);
    let mut out = header_text(cloud, &fields, data, viewpoint).into_bytes();
    let (packed, step) = body::packed_records(cloud, &fields);
    match data {
        PcdData::Binary => out.extend_from_slice(&packed),
        PcdData::Ascii => {
            out.extend_from_slice(body::ascii_lines(&fields, &packed, step)?.as_bytes())
        }
        PcdData::BinaryCompressed => {
            out.extend_from_slice(&body::compressed(&fields, &packed, step))
        }
    }
    Ok(out)
}

/// The header lines of `cloud` written with `fields` (in that order) and `data`.
fn header_text(
    cloud: &CloudView<'_>,
    fields: &[&PointField],
    data: PcdData,
    viewpoint: [f64; 7],
) -> String {
    let line = |key: &str, value: &dyn Fn(&PointField) -> String| {
        let values: Vec<String> = fields.iter().map(|f| value(f)).collect();
        format!("\n{key} {}", values.join(" "))
    };
    let mut header = String::from("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7");
    header.push_str(&line("FIELDS", &|f| f.name.clone()));
    header.push_str(&line("SIZE", &|f| f.datatype.size().to_string()));
    header.push_str(&line("TYPE", &|f| f.datatype.pcd_type().0.to_string()));
    header.push_str(&line("COUNT", &|f| f.count.max(1).to_string()));
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
    header
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::{Datatype, PointLayout};

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
