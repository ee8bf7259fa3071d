//! Reading the fields a perturbation needs out of any layout, and writing the result back into it.

use crate::cloud::{CloudView, FieldReader, names};
use crate::error::{Error, Result};
use crate::math::Portable;
use crate::sensor_model::{Axes, SensorModel};
use rayon::prelude::*;

/// The fields of a cloud as flat arrays (structure of arrays), in point order.
///
/// Positions are in the canonical frame of the sensor model's [`Axes`]: x forward, y left, z up
/// (for the usual x-forward, z-up sensors, the cloud's own coordinates). A perturbation that
/// moves points plans the new positions in this frame; [`crate::perturber::LidarPerturber`] turns
/// them back into the sensor's frame ([`Axes::to_sensor`], exact) before writing.
#[derive(Clone, Debug, Default)]
pub struct Points {
    /// x (forward) in metres.
    pub x: Vec<f32>,
    /// y (left) in metres.
    pub y: Vec<f32>,
    /// z (up) in metres.
    pub z: Vec<f32>,
    /// Intensity in the cloud's own units (see `intensity_max`), if the layout has one.
    pub intensity: Option<Vec<f32>>,
    /// Full-scale intensity of the sensor model: 1.0 or 255.0.
    pub intensity_max: f32,
    /// Ring per point, read from the layout or derived from elevation.
    pub ring: Option<Vec<u16>>,
    /// True if `ring` was derived from elevation rather than read.
    pub ring_derived: bool,
    /// The sensor's frame convention the positions were converted from.
    pub axes: Axes,
    /// The sensor model the points were read with (its beam elevations, azimuth resolution and
    /// range set the detector's sensor-derived parameters); `None` for points built by hand.
    pub sensor: Option<SensorModel>,
    /// The ring table of the last sensor model rings were derived for (kept between frames).
    ring_table: Option<RingTable>,
}

impl Points {
    /// Extracts x, y, z (into the canonical frame of `sensor.axes`), the intensity and (when
    /// `want_ring`) the ring from `cloud`. Fails with a clear error if the layout has no float x,
    /// y, z.
    pub fn extract(cloud: &CloudView<'_>, sensor: &SensorModel, want_ring: bool) -> Result<Self> {
        let mut p = Points::default();
        p.fill(cloud, sensor, want_ring)?;
        Ok(p)
    }

    /// Like [`Points::extract`], reusing this value's allocations.
    pub fn fill(
        &mut self,
        cloud: &CloudView<'_>,
        sensor: &SensorModel,
        want_ring: bool,
    ) -> Result<()> {
        let layout = cloud.layout();
        let [rx, ry, rz] = layout.xyz_readers()?;
        let n = cloud.len();
        let step = layout.point_step as usize;
        let ri = layout.reader_any(names::INTENSITY);
        let mut intensity = ri.map(|_| self.intensity.take().unwrap_or_default());
        let direct = |r: &FieldReader| r.is_le_f32_within(step) && cloud.is_contiguous();
        let read = |r: FieldReader, dst: &mut Vec<f32>| {
            dst.clear();
            dst.extend((0..n).map(|i| r.read_f32(cloud.point(i))));
        };
        if [rx, ry, rz].iter().all(direct) {
            // Little-endian f32 fields of points stored back to back (nearly every cloud): the
            // fields read in one pass over the points, without a per-point type test or row
            // arithmetic; the same values.
            match (ri, intensity.as_mut()) {
                (Some(ri), Some(v)) if direct(&ri) => {
                    self.fill_direct(cloud, [rx, ry, rz], Some((ri, v)))
                }
                (ri, v) => {
                    self.fill_direct(cloud, [rx, ry, rz], None);
                    if let (Some(ri), Some(v)) = (ri, v) {
                        read(ri, v);
                    }
                }
            }
        } else {
            read(rx, &mut self.x);
            read(ry, &mut self.y);
            read(rz, &mut self.z);
            if let (Some(ri), Some(v)) = (ri, intensity.as_mut()) {
                read(ri, v);
            }
        }
        self.intensity = intensity;
        self.axes = sensor.axes;
        if self.sensor.as_ref() != Some(sensor) {
            self.sensor = Some(sensor.clone());
        }
        if !self.axes.is_canonical() {
            for i in 0..n {
                let q = self.axes.to_canonical([self.x[i], self.y[i], self.z[i]]);
                (self.x[i], self.y[i], self.z[i]) = (q[0], q[1], q[2]);
            }
        }
        self.intensity_max = sensor.intensity_max;
        self.ring_derived = false;
        self.ring = None;
        if want_ring {
            let mut ring = Vec::with_capacity(n);
            if let Some(rr) = layout.reader_any(names::RING) {
                ring.extend((0..n).map(|i| rr.read_f64(cloud.point(i)).clamp(0.0, 65535.0) as u16));
            } else {
                if self
                    .ring_table
                    .as_ref()
                    .is_none_or(|t| t.e != sensor.elevations_deg)
                {
                    self.ring_table = RingTable::new(sensor);
                }
                let (x, y, z) = (&self.x, &self.y, &self.z);
                let elevation = |i: usize| z[i].patan2((x[i] * x[i] + y[i] * y[i]).sqrt());
                match &self.ring_table {
                    Some(t) => ring.extend((0..n).map(|i| t.ring_of_elevation(elevation(i)))),
                    None => ring.extend((0..n).map(|i| sensor.ring_of_elevation(elevation(i)))),
                }
                self.ring_derived = true;
            }
            self.ring = Some(ring);
        }
        Ok(())
    }

    /// x, y, z and (when given) the intensity of a contiguous cloud whose fields are all
    /// little-endian f32 ([`FieldReader::is_le_f32_within`]), read in one pass.
    fn fill_direct(
        &mut self,
        cloud: &CloudView<'_>,
        [rx, ry, rz]: [FieldReader; 3],
        intensity: Option<(FieldReader, &mut Vec<f32>)>,
    ) {
        let n = cloud.len();
        let step = cloud.layout().point_step as usize;
        let points = cloud.data()[..n * step].chunks_exact(step);
        for v in [&mut self.x, &mut self.y, &mut self.z] {
            v.clear();
            v.resize(n, 0.0);
        }
        let (ox, oy, oz) = (rx.offset, ry.offset, rz.offset);
        let xyz = self.x.iter_mut().zip(&mut self.y).zip(&mut self.z);
        match intensity {
            Some((ri, v)) => {
                let oi = ri.offset;
                v.clear();
                v.resize(n, 0.0);
                for ((((x, y), z), i), p) in xyz.zip(v.iter_mut()).zip(points) {
                    (*x, *y, *z, *i) = (le_f32(p, ox), le_f32(p, oy), le_f32(p, oz), le_f32(p, oi));
                }
            }
            None => {
                for (((x, y), z), p) in xyz.zip(points) {
                    (*x, *y, *z) = (le_f32(p, ox), le_f32(p, oy), le_f32(p, oz));
                }
            }
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True if there are no points.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Position of point `i`.
    #[inline]
    pub fn xyz(&self, i: usize) -> [f32; 3] {
        [self.x[i], self.y[i], self.z[i]]
    }

    /// Position of point `i` in the sensor's own frame.
    #[inline]
    pub fn sensor_xyz(&self, i: usize) -> [f32; 3] {
        self.axes.to_sensor(self.xyz(i))
    }

    /// Euclidean range of point `i` from the sensor origin.
    #[inline]
    pub fn range(&self, i: usize) -> f32 {
        (self.x[i] * self.x[i] + self.y[i] * self.y[i] + self.z[i] * self.z[i]).sqrt()
    }

    /// Intensity of point `i` in the cloud's units (0 if the cloud has none).
    #[inline]
    pub fn intensity(&self, i: usize) -> f32 {
        self.intensity.as_ref().map_or(0.0, |v| v[i])
    }
}

/// [`SensorModel::ring_of_elevation`] with the binary search replaced by a table lookup and a
/// short linear step, giving the same ring for every input: the search's branches are
/// unpredictable and cost more than the rest of deriving a ring. Built once per sensor model and
/// kept by [`Points`] between frames.
#[derive(Clone, Debug)]
struct RingTable {
    /// The sensor's elevations in degrees (ascending).
    e: Vec<f32>,
    /// `start[b]`: how many elevations lie below the lower edge of bin `b - 1` (a lower bound of
    /// the count below any angle in bin `b`).
    start: Vec<u16>,
    lo: f32,
    inv_step: f32,
}

impl RingTable {
    /// Bin width, degrees: a fraction of the finest spacing of any sensor's beams.
    const STEP_DEG: f32 = 0.05;

    /// The table of `sensor`, or `None` for an unusual elevation list (not strictly ascending,
    /// not finite, empty or huge), whose rings the search itself derives.
    fn new(sensor: &SensorModel) -> Option<Self> {
        let e = &sensor.elevations_deg[..];
        let ascending = e.windows(2).all(|w| w[0] < w[1]) && e.iter().all(|v| v.is_finite());
        let (&lo, &hi) = (e.first()?, e.last()?);
        if !ascending || e.len() >= 65_536 {
            return None;
        }
        let bins = ((hi - lo) / Self::STEP_DEG) as usize + 2;
        let start = (0..bins)
            .map(|b| {
                let edge = lo + b.saturating_sub(1) as f32 * Self::STEP_DEG;
                e.partition_point(|&v| v < edge) as u16
            })
            .collect();
        Some(RingTable {
            e: e.to_vec(),
            start,
            lo,
            inv_step: 1.0 / Self::STEP_DEG,
        })
    }

    #[inline]
    fn ring_of_elevation(&self, elevation: f32) -> u16 {
        let deg = elevation.to_degrees();
        let e = &self.e[..];
        // `i` = how many elevations lie below `deg` (the search's partition point): from the
        // table's lower bound, step up.
        let mut i = if deg >= self.lo {
            let b = ((deg - self.lo) * self.inv_step) as usize;
            self.start.get(b).map_or(e.len(), |&s| s as usize)
        } else {
            0
        };
        if i == e.len() {
            i = e.partition_point(|&v| v < deg);
        }
        while i < e.len() && e[i] < deg {
            i += 1;
        }
        if i == 0 {
            return 0;
        }
        if i >= e.len() {
            return (e.len() - 1) as u16;
        }
        // The nearer beam, the lower one on a tie; without a branch (the two are equally
        // likely, so a branch mispredicts half the time).
        let upper = (e[i] - deg).abs() < (deg - e[i - 1]).abs();
        (i - 1 + upper as usize) as u16
    }
}

/// The little-endian f32 at byte `o` of `p`.
#[inline(always)]
fn le_f32(p: &[u8], o: usize) -> f32 {
    f32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]])
}

/// Flag: the output point has a new position.
pub const MOVED: u8 = 1;
/// Flag: the output point has a new intensity.
pub const NEW_INTENSITY: u8 = 2;

/// The output of a LiDAR perturbation, one entry per output point: the input point it is made
/// from (all its other fields are copied), and the new position and intensity where flagged.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plan {
    /// Source point index per output point.
    pub src: Vec<u32>,
    /// New position (valid where `flags & MOVED`).
    pub xyz: Vec<[f32; 3]>,
    /// New intensity in the cloud's units (valid where `flags & NEW_INTENSITY`).
    pub intensity: Vec<f32>,
    /// [`MOVED`] | [`NEW_INTENSITY`].
    pub flags: Vec<u8>,
}

/// Shape of a written cloud.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CloudShape {
    /// Points per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bytes per row.
    pub row_step: usize,
    /// Bytes written.
    pub bytes: usize,
}

impl Plan {
    /// Empties the plan, keeping its allocations.
    pub fn clear(&mut self) {
        self.src.clear();
        self.xyz.clear();
        self.intensity.clear();
        self.flags.clear();
    }

    /// Output points so far.
    pub fn len(&self) -> usize {
        self.src.len()
    }

    /// True if the plan has no points.
    pub fn is_empty(&self) -> bool {
        self.src.is_empty()
    }

    /// Keeps input point `i` unchanged.
    #[inline]
    pub fn keep(&mut self, i: usize) {
        self.push(i, [0.0; 3], 0.0, 0);
    }

    /// Keeps input point `i` at a new position.
    #[inline]
    pub fn moved(&mut self, i: usize, xyz: [f32; 3]) {
        self.push(i, xyz, 0.0, MOVED);
    }

    /// Keeps input point `i` with a new intensity.
    #[inline]
    pub fn dimmed(&mut self, i: usize, intensity: f32) {
        self.push(i, [0.0; 3], intensity, NEW_INTENSITY);
    }

    /// Emits a point made from input point `i` with a new position and intensity (a moved point, a
    /// scattering return, a ghost copy).
    #[inline]
    pub fn emit(&mut self, i: usize, xyz: [f32; 3], intensity: f32) {
        self.push(i, xyz, intensity, MOVED | NEW_INTENSITY);
    }

    /// Appends an entry with explicit flags.
    #[inline]
    pub fn push(&mut self, i: usize, xyz: [f32; 3], intensity: f32, flags: u8) {
        self.src.push(i as u32);
        self.xyz.push(xyz);
        self.intensity.push(intensity);
        self.flags.push(flags);
    }

    /// Turns the new positions (planned in the canonical frame) into the sensor frame of `axes`;
    /// nothing to do for a canonical sensor.
    pub fn positions_to_sensor(&mut self, axes: &Axes) {
        if axes.is_canonical() {
            return;
        }
        for (p, f) in self.xyz.iter_mut().zip(&self.flags) {
            if f & MOVED != 0 {
                *p = axes.to_sensor(*p);
            }
        }
    }

    /// Keeps every input point unchanged.
    pub fn keep_all(&mut self, n: usize) {
        for i in 0..n {
            self.keep(i);
        }
    }

    /// True if the plan has exactly the input points in input order (so an organised cloud can keep
    /// its height and width).
    pub fn is_one_to_one(&self, n: usize) -> bool {
        self.src.len() == n && self.src.iter().enumerate().all(|(k, &s)| s as usize == k)
    }

    /// Bytes the output needs for `input`'s layout.
    pub fn output_bytes(&self, input: &CloudView<'_>) -> usize {
        self.len() * input.layout().point_step as usize
    }

    /// [`Plan::write`]'s points for a contiguous input whose x, y, z (at `xyz`) and intensity (at
    /// `intensity`) are little-endian f32: the same bytes, each field written as the four bytes at
    /// its offset, without a per-point type test or row arithmetic.
    fn write_direct(
        &self,
        input: &CloudView<'_>,
        xyz: [usize; 3],
        intensity: Option<usize>,
        out: &mut [u8],
    ) {
        let step = input.layout().point_step as usize;
        let data = input.data();
        let put =
            |dst: &mut [u8], o: usize, v: f32| dst[o..o + 4].copy_from_slice(&v.to_le_bytes());
        out.par_chunks_mut(step * 1024)
            .enumerate()
            .for_each(|(block, chunk)| {
                let k0 = block * 1024;
                let n = chunk.len() / step;
                let plan = self.src[k0..k0 + n]
                    .iter()
                    .zip(&self.flags[k0..k0 + n])
                    .zip(&self.xyz[k0..k0 + n])
                    .zip(&self.intensity[k0..k0 + n]);
                for (dst, (((&src, &f), p), &v)) in chunk.chunks_exact_mut(step).zip(plan) {
                    let s = src as usize * step;
                    dst.copy_from_slice(&data[s..s + step]);
                    if f & MOVED != 0 {
                        put(dst, xyz[0], p[0]);
                        put(dst, xyz[1], p[1]);
                        put(dst, xyz[2], p[2]);
                    }
                    if f & NEW_INTENSITY != 0
                        && let Some(o) = intensity
                    {
                        put(dst, o, v);
                    }
                }
            });
    }

    /// Writes the output cloud into `out` in `input`'s layout: each output point is a copy of its
    /// source point's bytes with x, y, z and the intensity field overwritten where flagged. An
    /// organised input (height > 1) keeps its height and width when the plan is one to one;
    /// otherwise the output is one row.
    pub fn write(&self, input: &CloudView<'_>, out: &mut [u8]) -> Result<CloudShape> {
        let layout = input.layout();
        let step = layout.point_step as usize;
        let needed = self.output_bytes(input);
        if out.len() < needed {
            return Err(Error::OutputTooSmall {
                needed,
                available: out.len(),
            });
        }
        let [rx, ry, rz] = layout.xyz_readers()?;
        let ri = layout.reader_any(names::INTENSITY);
        let fields = [Some(rx), Some(ry), Some(rz), ri];
        let direct =
            input.is_contiguous() && fields.iter().flatten().all(|r| r.is_le_f32_within(step));
        if step == 0 {
            // No bytes to write (an empty plan, or a layout without bytes).
        } else if direct {
            self.write_direct(
                input,
                [rx.offset, ry.offset, rz.offset],
                ri.map(|r| r.offset),
                &mut out[..needed],
            );
        } else {
            out[..needed]
                .par_chunks_mut(step * 1024)
                .enumerate()
                .for_each(|(block, chunk)| {
                    for (j, dst) in chunk.chunks_exact_mut(step).enumerate() {
                        let k = block * 1024 + j;
                        dst.copy_from_slice(input.point(self.src[k] as usize));
                        let f = self.flags[k];
                        if f & MOVED != 0 {
                            let p = self.xyz[k];
                            rx.write_f32(dst, p[0]);
                            ry.write_f32(dst, p[1]);
                            rz.write_f32(dst, p[2]);
                        }
                        if f & NEW_INTENSITY != 0
                            && let Some(ri) = ri
                        {
                            ri.write_f32(dst, self.intensity[k]);
                        }
                    }
                });
        }
        let (width, height) = if input.height > 1 && self.is_one_to_one(input.len()) {
            (input.width, input.height)
        } else {
            (self.len() as u32, 1)
        };
        Ok(CloudShape {
            width,
            height,
            row_step: width as usize * step,
            bytes: needed,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::{Cloud, Datatype, PointField, PointLayout};
    use std::sync::Arc;

    fn odd_layout() -> PointLayout {
        PointLayout::new(
            vec![
                PointField::new("intensity", 0, Datatype::Uint8),
                PointField::new("x", 1, Datatype::Float32),
                PointField::new("y", 5, Datatype::Float32),
                PointField::new("z", 9, Datatype::Float64),
                PointField::new("ring", 17, Datatype::Uint16),
                PointField::new("time", 19, Datatype::Float32),
            ],
            26,
            true,
        )
        .unwrap()
    }

    #[test]
    fn the_ring_table_gives_the_search_s_ring_for_every_elevation() {
        for m in [
            SensorModel::vlp32c(),
            SensorModel::vlp16(),
            SensorModel::hdl32e(),
            SensorModel::hdl64e(),
            SensorModel::nuscenes(),
        ] {
            let t = RingTable::new(&m).expect("a table for every built-in model");
            let mut deg = -40.0f32;
            let mut all: Vec<f32> = Vec::new();
            while deg < 40.0 {
                all.push(deg);
                deg += 0.001 + deg.abs() * 1e-6;
            }
            // The beams themselves, their midpoints and the floats next to them.
            for w in m.elevations_deg.windows(2) {
                let mid = (w[0] + w[1]) / 2.0;
                for v in [w[0], w[1], mid] {
                    all.extend([v, v.next_up(), v.next_down()]);
                }
            }
            all.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 90.0, -90.0]);
            for d in all {
                let el = d.to_radians();
                assert_eq!(
                    t.ring_of_elevation(el),
                    m.ring_of_elevation(el),
                    "{} at {d} deg",
                    m.name
                );
            }
        }
    }

    #[test]
    fn extract_and_write_round_trip_in_an_odd_layout() {
        let layout = odd_layout();
        let cloud = Cloud::from_xyzi(&layout, &[[1.0, 2.0, 3.0, 40.0], [4.0, 5.0, 6.0, 250.0]]);
        let t = layout.reader("time").unwrap();
        let mut cloud = cloud;
        t.write_f32(&mut cloud.data[26..], 0.05);
        let view = cloud.view();
        let pts = Points::extract(&view, &SensorModel::vlp32c(), true).unwrap();
        assert_eq!(pts.xyz(1), [4.0, 5.0, 6.0]);
        assert_eq!(pts.intensity(1), 250.0);
        assert!(!pts.ring_derived);

        let mut plan = Plan::default();
        plan.keep(1);
        plan.emit(0, [7.0, 8.0, 9.0], 12.0);
        let mut out = vec![0u8; plan.output_bytes(&view)];
        let shape = plan.write(&view, &mut out).unwrap();
        assert_eq!((shape.width, shape.height), (2, 1));
        assert_eq!(
            &out[..26],
            &cloud.data[26..52],
            "kept point is byte-identical"
        );
        let outv =
            crate::cloud::CloudView::new(Arc::new(layout.clone()), &out, 2, 1, 52, true).unwrap();
        let back = Points::extract(&outv, &SensorModel::vlp32c(), false).unwrap();
        assert_eq!(back.xyz(1), [7.0, 8.0, 9.0]);
        assert_eq!(back.intensity(1), 12.0);
        assert_eq!(
            t.read_f32(outv.point(0)),
            0.05,
            "untouched fields pass through"
        );
    }

    /// The same points (LE f32 x, y, z, intensity and a u16 ring) stored back to back and as
    /// two rows with padding: the direct paths (contiguous) against the per-field ones.
    #[test]
    fn direct_reads_and_writes_equal_the_per_field_ones() {
        let layout = Arc::new(
            PointLayout::new(
                vec![
                    PointField::new("ring", 0, Datatype::Uint16),
                    PointField::new("z", 2, Datatype::Float32),
                    PointField::new("x", 6, Datatype::Float32),
                    PointField::new("intensity", 10, Datatype::Float32),
                    PointField::new("y", 14, Datatype::Float32),
                ],
                18,
                false,
            )
            .unwrap(),
        );
        let (w, step) = (37usize, 18usize);
        let mut rng = crate::rng::Rng::from_key(17);
        let packed: Vec<u8> = (0..2 * w * step).map(|_| rng.next_u32() as u8).collect();
        let pad = 5;
        let mut padded = Vec::new();
        for row in packed.chunks_exact(w * step) {
            padded.extend_from_slice(row);
            padded.extend(std::iter::repeat_n(0xEE, pad));
        }
        let a = CloudView::new(layout.clone(), &packed, w as u32, 2, w * step, false).unwrap();
        let b = CloudView::new(layout, &padded, w as u32, 2, w * step + pad, false).unwrap();
        assert!(a.is_contiguous() && !b.is_contiguous());
        let sensor = SensorModel::vlp32c();
        let (pa, pb) = (
            Points::extract(&a, &sensor, true).unwrap(),
            Points::extract(&b, &sensor, true).unwrap(),
        );
        let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&pa.x), bits(&pb.x));
        assert_eq!(bits(&pa.y), bits(&pb.y));
        assert_eq!(bits(&pa.z), bits(&pb.z));
        assert_eq!(
            bits(pa.intensity.as_deref().unwrap()),
            bits(pb.intensity.as_deref().unwrap())
        );
        assert_eq!(pa.ring, pb.ring);
        let mut plan = Plan::default();
        for i in 0..2 * w {
            match i % 5 {
                0 => plan.keep(i),
                1 => plan.moved(i, [i as f32, -1.5, 2.25]),
                2 => plan.dimmed(i, 0.125 * i as f32),
                3 => plan.emit(2 * w - 1 - i, [0.5, i as f32, -3.0], 7.0),
                _ => {}
            }
        }
        let mut out_a = vec![0u8; plan.output_bytes(&a)];
        let mut out_b = vec![1u8; plan.output_bytes(&b)];
        assert_eq!(
            plan.write(&a, &mut out_a).unwrap(),
            plan.write(&b, &mut out_b).unwrap()
        );
        assert_eq!(out_a, out_b);
    }

    #[test]
    fn ring_is_derived_from_elevation_when_absent() {
        let layout = PointLayout::xyzi_f32();
        let d = 10.0f32;
        let low = (-25.0f32).to_radians().ptan() * d;
        let cloud = Cloud::from_xyzi(&layout, &[[d, 0.0, low, 0.0], [d, 0.0, 0.0, 0.0]]);
        let pts = Points::extract(&cloud.view(), &SensorModel::vlp32c(), true).unwrap();
        assert!(pts.ring_derived);
        assert_eq!(pts.ring.unwrap(), vec![0, 20]);
    }

    #[test]
    fn write_refuses_a_short_buffer() {
        let cloud = Cloud::from_xyzi(&PointLayout::xyzi_f32(), &[[1.0, 1.0, 1.0, 1.0]]);
        let mut plan = Plan::default();
        plan.keep_all(1);
        let err = plan.write(&cloud.view(), &mut [0u8; 8]).unwrap_err();
        assert!(matches!(
            err,
            Error::OutputTooSmall {
                needed: 16,
                available: 8
            }
        ));
    }
}
