//! Raw float32 point files: KITTI velodyne `.bin` (x, y, z, reflectance) and nuScenes `.pcd.bin`
//! (x, y, z, intensity, ring index).

use crate::cloud::{Cloud, CloudView, Datatype, PointField, PointLayout};
use crate::error::{Error, Result};
use std::sync::Arc;

/// The nuScenes `.pcd.bin` layout: five little-endian float32 per point.
pub fn nuscenes_layout() -> PointLayout {
    PointLayout {
        fields: vec![
            PointField::new("x", 0, Datatype::Float32),
            PointField::new("y", 4, Datatype::Float32),
            PointField::new("z", 8, Datatype::Float32),
            PointField::new("intensity", 12, Datatype::Float32),
            PointField::new("ring", 16, Datatype::Float32),
        ],
        point_step: 20,
        big_endian: false,
    }
}

fn decode_f32_records(bytes: &[u8], layout: PointLayout, what: &'static str) -> Result<Cloud> {
    let step = layout.point_step as usize;
    if !bytes.len().is_multiple_of(step) {
        return Err(Error::malformed(
            what,
            format!(
                "size {} is not a multiple of {step} bytes per point ({} whole points and {} bytes left over): truncated or not this format",
                bytes.len(),
                bytes.len() / step,
                bytes.len() % step
            ),
        ));
    }
    let n = bytes.len() / step;
    let dense = bytes
        .chunks_exact(4)
        .all(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]).is_finite());
    Cloud::from_vec(
        Arc::new(layout),
        bytes.to_vec(),
        n as u32,
        1,
        n * step,
        dense,
    )
}

/// Decodes a KITTI velodyne `.bin`: float32 x, y, z, reflectance (0..1) per point. A size that
/// is not a multiple of 16 bytes is an error (its message says when the size fits nuScenes' 20
/// bytes per point instead); [`kitti_doubts`] says when a file that decodes may not be KITTI.
pub fn decode_kitti(bytes: &[u8]) -> Result<Cloud> {
    decode_f32_records(bytes, PointLayout::xyzi_f32(), "KITTI .bin").map_err(|e| {
        if !bytes.len().is_multiple_of(16) && bytes.len().is_multiple_of(20) {
            Error::malformed(
                "KITTI .bin",
                format!(
                    "{e}; its size is a multiple of 20 bytes, as a nuScenes .pcd.bin's (x, y, z, intensity, ring): rename it to .pcd.bin if it is one"
                ),
            )
        } else {
            e
        }
    })
}

/// Whether every value is a whole number within 0..=127 and there are at least `distinct` of
/// them, as ring indices are.
fn ring_like(values: impl Iterator<Item = f32>, distinct: usize) -> bool {
    let mut seen = [false; 128];
    for v in values {
        if !(v.is_finite() && (0.0..=127.0).contains(&v) && v.fract() == 0.0) {
            return false;
        }
        seen[v as usize] = true;
    }
    seen.iter().filter(|s| **s).count() >= distinct
}

/// Reasons to doubt that `bytes`, which decode as a KITTI `.bin`, are a KITTI scan, one sentence
/// each (empty when nothing looks wrong): the size also fits nuScenes' five floats per point and
/// every fifth float is a ring number; the 4th column holds small whole numbers (a ring index, not
/// a reflectance); the 4th column leaves KITTI's 0..1 reflectance range.
pub fn kitti_doubts(bytes: &[u8]) -> Vec<String> {
    let mut out = Vec::new();
    if bytes.is_empty() || !bytes.len().is_multiple_of(16) {
        return out;
    }
    let floats: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if bytes.len().is_multiple_of(20) && ring_like(floats.iter().skip(4).step_by(5).copied(), 4) {
        out.push(format!(
            "its size ({} bytes) is also a multiple of 20 and every fifth float is a small whole number, as in a nuScenes .pcd.bin (x, y, z, intensity, ring): read as KITTI's four floats per point, the points are garbage; rename it to .pcd.bin if it is one",
            bytes.len()
        ));
        return out;
    }
    let fourth = || floats.iter().skip(3).step_by(4).copied();
    if ring_like(fourth(), 8) {
        out.push(
            "its 4th column holds only small whole numbers, like a ring index, not KITTI's reflectance (0..1): read as reflectance"
                .into(),
        );
    } else {
        let max = fourth().filter(|v| v.is_finite()).fold(0f32, f32::max);
        if max > 1.0 {
            out.push(format!(
                "its 4th column reaches {max}, beyond KITTI's reflectance range 0..1: if it holds 0..255 intensities, say so with --intensity-max 255"
            ));
        }
    }
    out
}

/// Decodes a nuScenes `.pcd.bin`: float32 x, y, z, intensity, ring per point.
pub fn decode_nuscenes(bytes: &[u8]) -> Result<Cloud> {
    decode_f32_records(bytes, nuscenes_layout(), "nuScenes .pcd.bin")
}

fn encode_f32_records(cloud: &CloudView<'_>, layout: &PointLayout) -> Result<Vec<u8>> {
    if cloud.layout() == layout {
        let step = layout.point_step as usize;
        let mut out = Vec::with_capacity(cloud.len() * step);
        for i in 0..cloud.len() {
            out.extend_from_slice(cloud.point(i));
        }
        return Ok(out);
    }
    // Another layout: convert field by field (missing optional fields are written as 0).
    let src = cloud.layout();
    let readers: Vec<_> = layout
        .fields
        .iter()
        .map(|f| {
            let name = f.name.as_str();
            let found = match name {
                "intensity" => src.reader_any(crate::cloud::names::INTENSITY),
                "ring" => src.reader_any(crate::cloud::names::RING),
                _ => src.reader(name),
            };
            match (name, found) {
                (_, Some(r)) => Ok(Some(r)),
                ("x" | "y" | "z", None) => Err(Error::MissingField {
                    field: "x, y or z",
                    hint: "",
                }),
                (_, None) => Ok(None),
            }
        })
        .collect::<Result<_>>()?;
    let mut out = Vec::with_capacity(cloud.len() * layout.point_step as usize);
    for i in 0..cloud.len() {
        let p = cloud.point(i);
        for r in &readers {
            let v = r.map_or(0.0, |r| r.read_f32(p));
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    Ok(out)
}

/// Encodes as a KITTI `.bin` (a cloud in another layout is converted; a missing intensity is 0).
pub fn encode_kitti(cloud: &CloudView<'_>) -> Result<Vec<u8>> {
    encode_f32_records(cloud, &PointLayout::xyzi_f32())
}

/// Encodes as a nuScenes `.pcd.bin`.
pub fn encode_nuscenes(cloud: &CloudView<'_>) -> Result<Vec<u8>> {
    encode_f32_records(cloud, &nuscenes_layout())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kitti_round_trip_and_truncation() {
        let c = Cloud::from_xyzi(
            &PointLayout::xyzi_f32(),
            &[[1.0, 2.0, 3.0, 0.5], [4.0, 5.0, 6.0, 0.25]],
        );
        let bytes = encode_kitti(&c.view()).unwrap();
        assert_eq!(bytes.len(), 32);
        assert_eq!(decode_kitti(&bytes).unwrap(), c);
        let err = decode_kitti(&bytes[..30]).unwrap_err();
        assert!(err.to_string().contains("not a multiple of 16"), "{err}");
        assert!(decode_kitti(&[]).unwrap().is_empty());
    }

    #[test]
    fn doubtful_kitti_files_are_named() {
        // A real-looking KITTI scan: no doubt.
        let kitti: Vec<[f32; 4]> = (0..40)
            .map(|i| [i as f32 * 0.3, 1.0, -1.5, (i % 10) as f32 / 10.0])
            .collect();
        let bytes =
            encode_kitti(&Cloud::from_xyzi(&PointLayout::xyzi_f32(), &kitti).view()).unwrap();
        assert!(kitti_doubts(&bytes).is_empty());
        // nuScenes records (20 bytes) whose count makes the size a multiple of 16 too.
        let mut nus = Vec::new();
        for i in 0..40u32 {
            for v in [i as f32 * 0.3, 1.0, -1.5, 37.0, (i % 32) as f32] {
                nus.extend_from_slice(&v.to_le_bytes());
            }
        }
        assert_eq!(nus.len() % 80, 0);
        let d = kitti_doubts(&nus);
        assert!(d.len() == 1 && d[0].contains("nuScenes"), "{d:?}");
        // Not a multiple of 16: an error that points at nuScenes.
        let err = decode_kitti(&nus[..20 * 39]).unwrap_err().to_string();
        assert!(
            err.contains("multiple of 20") && err.contains(".pcd.bin"),
            "{err}"
        );
        // x, y, z, ring: the 4th column is a ring index.
        let ring: Vec<[f32; 4]> = (0..64)
            .map(|i| [i as f32 * 0.3, 1.0, -1.5, (i % 32) as f32])
            .collect();
        let bytes =
            encode_kitti(&Cloud::from_xyzi(&PointLayout::xyzi_f32(), &ring).view()).unwrap();
        let d = kitti_doubts(&bytes);
        assert!(d.len() == 1 && d[0].contains("ring index"), "{d:?}");
        // 0..255 intensities.
        let v255: Vec<[f32; 4]> = (0..64)
            .map(|i| [i as f32 * 0.3, 1.0, -1.5, i as f32 * 3.7])
            .collect();
        let bytes =
            encode_kitti(&Cloud::from_xyzi(&PointLayout::xyzi_f32(), &v255).view()).unwrap();
        assert!(kitti_doubts(&bytes)[0].contains("--intensity-max 255"));
    }

    #[test]
    fn nuscenes_from_kitti_layout_fills_ring_with_zero() {
        let c = Cloud::from_xyzi(&PointLayout::xyzi_f32(), &[[1.0, 2.0, 3.0, 9.0]]);
        let bytes = encode_nuscenes(&c.view()).unwrap();
        let back = decode_nuscenes(&bytes).unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!(&bytes[12..16], &9.0f32.to_le_bytes());
        assert_eq!(&bytes[16..20], &0.0f32.to_le_bytes());
    }
}
