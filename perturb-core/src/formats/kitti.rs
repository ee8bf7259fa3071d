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

/// Decodes a KITTI velodyne `.bin`: float32 x, y, z, reflectance (0..1) per point.
pub fn decode_kitti(bytes: &[u8]) -> Result<Cloud> {
    decode_f32_records(bytes, PointLayout::xyzi_f32(), "KITTI .bin")
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
    fn nuscenes_from_kitti_layout_fills_ring_with_zero() {
        let c = Cloud::from_xyzi(&PointLayout::xyzi_f32(), &[[1.0, 2.0, 3.0, 9.0]]);
        let bytes = encode_nuscenes(&c.view()).unwrap();
        let back = decode_nuscenes(&bytes).unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!(&bytes[12..16], &9.0f32.to_le_bytes());
        assert_eq!(&bytes[16..20], &0.0f32.to_le_bytes());
    }
}
