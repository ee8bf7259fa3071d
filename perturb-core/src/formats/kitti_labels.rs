//! KITTI object labels (`label_2/*.txt`) and calibration (`calib/*.txt`), and the conversion of a
//! labelled box into the velodyne frame, for comparing detections with ground truth.
//!
//! A label line is `type truncated occluded alpha left top right bottom h w l x y z rotation_y
//! [score]`. The box is in the rectified camera frame (x right, y down, z forward): `(x, y, z)` is
//! the centre of the box's **bottom** face, `h, w, l` its height, width and length, and
//! `rotation_y` the heading about the camera's y axis (0 = facing camera +x). Into the velodyne
//! frame (x forward, y left, z up): `p_velo = Tr_velo_to_cam^-1 R0_rect^-1 p_rect`, the centre is
//! lifted by h/2 along the camera's -y, and the heading is the image of the direction
//! `(cos ry, 0, -sin ry)`, which for KITTI's calibration is `-(pi/2 + ry)` to within a fraction
//! of a degree.
//!
//! ```
//! use perturb_core::formats::kitti_labels::{parse_labels, KittiCalib};
//! let calib = KittiCalib::parse("R0_rect: 1 0 0 0 1 0 0 0 1\n\
//!     Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n").unwrap();
//! let objs = parse_labels("Car 0.00 0 0.0 0 0 10 10 1.5 1.6 4.0 2.0 1.7 10.0 0.0\n").unwrap();
//! let b = calib.to_velodyne(&objs[0]);
//! assert!((b.center[0] - 10.0).abs() < 1e-5 && (b.center[1] + 2.0).abs() < 1e-5);
//! assert!((b.center[2] - (-1.7 + 0.75)).abs() < 1e-5);
//! assert!((b.yaw + std::f32::consts::FRAC_PI_2).abs() < 1e-5);
//! assert_eq!(b.size, [4.0, 1.6, 1.5]);
//! ```

use crate::error::{Error, Result};
use crate::lidar::Box3;

/// One labelled object of a KITTI `label_2` file.
#[derive(Clone, Debug, PartialEq)]
pub struct KittiObject {
    /// Class (`Car`, `Pedestrian`, `Cyclist`, `Van`, `Truck`, `DontCare`, ...).
    pub kind: String,
    /// Truncation, 0 (inside the image) .. 1.
    pub truncated: f32,
    /// Occlusion state 0..3 (-1 for DontCare).
    pub occluded: i32,
    /// Observation angle in radians.
    pub alpha: f32,
    /// 2-D box in the image: left, top, right, bottom, pixels.
    pub bbox: [f32; 4],
    /// Height, width, length in metres.
    pub hwl: [f32; 3],
    /// Bottom-centre in the rectified camera frame, metres.
    pub location: [f32; 3],
    /// Heading about the camera y axis, radians.
    pub rotation_y: f32,
    /// Detection score (result files only).
    pub score: Option<f32>,
}

impl KittiObject {
    /// False for `DontCare` regions (no 3-D box).
    pub fn has_box(&self) -> bool {
        self.kind != "DontCare" && self.hwl.iter().all(|v| *v > 0.0)
    }
}

fn num(tok: Option<&str>, what: &str, line: usize) -> Result<f32> {
    let t = tok.ok_or_else(|| {
        Error::malformed(
            "KITTI label",
            format!("line {line}: missing field `{what}`"),
        )
    })?;
    t.parse::<f32>().map_err(|_| {
        Error::malformed(
            "KITTI label",
            format!("line {line}: field `{what}` is `{t}`, not a number"),
        )
    })
}

/// Parses a `label_2` file (blank lines skipped).
pub fn parse_labels(text: &str) -> Result<Vec<KittiObject>> {
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let ln = k + 1;
        let mut t = line.split_whitespace();
        let Some(kind) = t.next() else { continue };
        let truncated = num(t.next(), "truncated", ln)?;
        let occluded = num(t.next(), "occluded", ln)? as i32;
        let alpha = num(t.next(), "alpha", ln)?;
        let mut bbox = [0f32; 4];
        for (v, name) in bbox.iter_mut().zip(["left", "top", "right", "bottom"]) {
            *v = num(t.next(), name, ln)?;
        }
        let mut hwl = [0f32; 3];
        for (v, name) in hwl.iter_mut().zip(["height", "width", "length"]) {
            *v = num(t.next(), name, ln)?;
        }
        let mut location = [0f32; 3];
        for (v, name) in location.iter_mut().zip(["x", "y", "z"]) {
            *v = num(t.next(), name, ln)?;
        }
        let rotation_y = num(t.next(), "rotation_y", ln)?;
        let score = match t.next() {
            Some(s) => Some(num(Some(s), "score", ln)?),
            None => None,
        };
        out.push(KittiObject {
            kind: kind.to_string(),
            truncated,
            occluded,
            alpha,
            bbox,
            hwl,
            location,
            rotation_y,
            score,
        });
    }
    Ok(out)
}

/// The two matrices of a KITTI calibration file that relate the velodyne and the rectified camera.
#[derive(Clone, Debug, PartialEq)]
pub struct KittiCalib {
    /// Rectifying rotation (row-major 3 x 3).
    pub r0_rect: [[f64; 3]; 3],
    /// Velodyne to (unrectified) camera, row-major 3 x 4.
    pub tr_velo_to_cam: [[f64; 4]; 3],
    /// Projection of the rectified frame into the left colour camera's image (`P2`, row-major
    /// 3 x 4), if the file has it.
    pub p2: Option<[[f64; 4]; 3]>,
}

impl KittiCalib {
    /// Parses a calibration file (`R0_rect:` 9 numbers and `Tr_velo_to_cam:` 12 numbers; the
    /// other lines are ignored).
    pub fn parse(text: &str) -> Result<Self> {
        let mut r0 = None;
        let mut tr = None;
        let mut p2 = None;
        for line in text.lines() {
            let Some((key, rest)) = line.split_once(':') else {
                continue;
            };
            let vals: std::result::Result<Vec<f64>, _> =
                rest.split_whitespace().map(str::parse::<f64>).collect();
            let bad = || Error::malformed("KITTI calib", format!("`{}` is malformed", key.trim()));
            match key.trim() {
                "R0_rect" | "R_rect" => {
                    let v = vals.map_err(|_| bad())?;
                    if v.len() != 9 {
                        return Err(bad());
                    }
                    r0 = Some([[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]);
                }
                k @ ("Tr_velo_to_cam" | "Tr_velo_cam" | "P2") => {
                    let v = vals.map_err(|_| bad())?;
                    if v.len() != 12 {
                        return Err(bad());
                    }
                    let m = [
                        [v[0], v[1], v[2], v[3]],
                        [v[4], v[5], v[6], v[7]],
                        [v[8], v[9], v[10], v[11]],
                    ];
                    if k == "P2" {
                        p2 = Some(m);
                    } else {
                        tr = Some(m);
                    }
                }
                _ => {}
            }
        }
        match (r0, tr) {
            (Some(r0_rect), Some(tr_velo_to_cam)) => Ok(KittiCalib {
                r0_rect,
                tr_velo_to_cam,
                p2,
            }),
            _ => Err(Error::malformed(
                "KITTI calib",
                "needs both `R0_rect` and `Tr_velo_to_cam`",
            )),
        }
    }

    /// A point of the rectified camera frame in the velodyne frame.
    pub fn rect_to_velo(&self, p: [f64; 3]) -> [f64; 3] {
        // R0 is a rotation: its inverse is its transpose.
        let r = &self.r0_rect;
        let cam = [0, 1, 2].map(|j| r[0][j] * p[0] + r[1][j] * p[1] + r[2][j] * p[2]);
        // Tr = [R | t]: velo = R^T (cam - t).
        let t = &self.tr_velo_to_cam;
        let d = [cam[0] - t[0][3], cam[1] - t[1][3], cam[2] - t[2][3]];
        [0, 1, 2].map(|j| t[0][j] * d[0] + t[1][j] * d[1] + t[2][j] * d[2])
    }

    /// A point of the velodyne frame in the rectified camera frame.
    pub fn velo_to_rect(&self, p: [f64; 3]) -> [f64; 3] {
        let t = &self.tr_velo_to_cam;
        let cam = [0, 1, 2].map(|k| t[k][0] * p[0] + t[k][1] * p[1] + t[k][2] * p[2] + t[k][3]);
        let r = &self.r0_rect;
        [0, 1, 2].map(|k| r[k][0] * cam[0] + r[k][1] * cam[1] + r[k][2] * cam[2])
    }

    /// The pixel (column, row) of the colour camera image where the velodyne point `p` projects
    /// with `P2`, or `None` when the file has no `P2` or the point is not in front of the camera.
    pub fn velo_to_image(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        let p2 = self.p2.as_ref()?;
        let r = self.velo_to_rect(p);
        let q = [0, 1, 2].map(|k| p2[k][0] * r[0] + p2[k][1] * r[1] + p2[k][2] * r[2] + p2[k][3]);
        (q[2] > 0.1).then(|| [q[0] / q[2], q[1] / q[2]])
    }

    /// True if the velodyne point `p` projects inside a `width` x `height` image of the colour
    /// camera (the camera's field of view). False without `P2`.
    pub fn in_image(&self, p: [f64; 3], width: u32, height: u32) -> bool {
        self.velo_to_image(p)
            .is_some_and(|[u, v]| u >= 0.0 && u < width as f64 && v >= 0.0 && v < height as f64)
    }

    /// A direction of the rectified camera frame in the velodyne frame (rotation only).
    pub fn rect_dir_to_velo(&self, d: [f64; 3]) -> [f64; 3] {
        let o = self.rect_to_velo([0.0; 3]);
        let p = self.rect_to_velo(d);
        [p[0] - o[0], p[1] - o[1], p[2] - o[2]]
    }

    /// The object's 3-D box in the velodyne frame: centre (not bottom), size [length, width,
    /// height], heading about +z.
    pub fn to_velodyne(&self, o: &KittiObject) -> Box3 {
        let [h, w, l] = o.hwl.map(|v| v as f64);
        let [x, y, z] = o.location.map(|v| v as f64);
        let c = self.rect_to_velo([x, y - h / 2.0, z]);
        let ry = o.rotation_y as f64;
        let d = self.rect_dir_to_velo([crate::math::cos(ry), 0.0, -crate::math::sin(ry)]);
        Box3 {
            center: c.map(|v| v as f32),
            size: [l as f32, w as f32, h as f32],
            yaw: crate::math::atan2(d[1], d[0]) as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_lines_are_named() {
        let err = parse_labels("Car 0 0 0 1 2 3\n").unwrap_err();
        assert!(err.to_string().contains("line 1"), "{err}");
        let err = parse_labels("\nCar 0 0 x 1 2 3 4 1 1 1 1 1 1 0\n").unwrap_err();
        assert!(err.to_string().contains("line 2") && err.to_string().contains("alpha"));
        assert!(KittiCalib::parse("R0_rect: 1 0 0\n").is_err());
        let objs =
            parse_labels("DontCare -1 -1 -10 1 2 3 4 -1 -1 -1 -1000 -1000 -1000 -10\n").unwrap();
        assert!(!objs[0].has_box());
    }

    #[test]
    fn heading_matches_the_usual_formula_on_kitti_calibration() {
        let calib = KittiCalib::parse(
            "R0_rect: 9.999239e-01 9.837760e-03 -7.445048e-03 -9.869795e-03 9.999421e-01 -4.278459e-03 7.402527e-03 4.351614e-03 9.999631e-01\n\
             Tr_velo_to_cam: 7.533745e-03 -9.999714e-01 -6.166020e-04 -4.069766e-03 1.480249e-02 7.280733e-04 -9.998902e-01 -7.631618e-02 9.998621e-01 7.523790e-03 1.480755e-02 -2.717806e-01\n",
        )
        .unwrap();
        for ry in [-3.0f32, -1.57, -0.5, 0.0, 1.0, 2.5] {
            let o = KittiObject {
                kind: "Car".into(),
                truncated: 0.0,
                occluded: 0,
                alpha: 0.0,
                bbox: [0.0; 4],
                hwl: [1.5, 1.6, 4.0],
                location: [1.0, 1.7, 10.0],
                rotation_y: ry,
                score: None,
            };
            let b = calib.to_velodyne(&o);
            let want = -(std::f32::consts::FRAC_PI_2 + ry);
            let d = (b.yaw - want).rem_euclid(std::f32::consts::TAU);
            assert!(d.min(std::f32::consts::TAU - d) < 0.02, "ry {ry}");
            // The sensor sits 1.73 m above the road: a car on the road has its centre near -1.
            assert!((b.center[2] + 0.95).abs() < 0.2, "{:?}", b.center);
        }
    }
}
