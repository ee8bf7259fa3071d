//! Frames in any `sensor_msgs/Image` encoding of perturb-core's encoding table (Bayer, YUV
//! 4:2:2, 16-bit, the 8-bit layouts): `perturb.encodings()` lists the table,
//! `perturb.apply_encoded(...)` perturbs a frame's bytes through its working view and returns
//! them in the frame's own encoding, size, step and byte order, byte-identical to perturbd and
//! `perturb apply` on a bag for the same ID, severity, seed and sequence number.

use super::{Count, Seed, Seq, Severity, detach, perr, spec};
use perturb_core::encoding::{ENCODINGS, EncodedView, Layout, Scratch};
use perturb_core::perturber::CameraPerturber;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

/// The encoding table: a list of dicts with `name`, `aliases`, `layout` (`direct`, `bayer` or
/// `yuv422`), `bits` (of a sample), `bytes_per_pixel`, `tile` ([width, height] multiples),
/// `working` (the 8-bit layout perturbations run on), `opencv` (the code cv_bridge converts it
/// to BGR with, or None) and `summary`.
#[pyfunction]
pub fn encodings(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for e in &ENCODINGS {
        let d = PyDict::new(py);
        d.set_item("name", e.name)?;
        d.set_item("aliases", e.aliases.to_vec())?;
        let layout = match e.layout {
            Layout::Direct(_) => "direct",
            Layout::Bayer(_) => "bayer",
            Layout::Yuv422(_) => "yuv422",
        };
        d.set_item("layout", layout)?;
        d.set_item("bits", e.bits)?;
        d.set_item("bytes_per_pixel", e.bytes_per_pixel())?;
        let (tw, th, _) = e.tile();
        d.set_item("tile", vec![tw, th])?;
        d.set_item("working", e.working_format().ros_encoding())?;
        d.set_item("opencv", e.opencv_to_bgr())?;
        d.set_item("summary", e.summary)?;
        out.append(d)?;
    }
    Ok(out)
}

/// Perturbs the bytes of one image (`data`, `step * height` bytes as in a `sensor_msgs/Image`)
/// in `encoding` with perturbation `id` at `severity`, `seed`, frame sequence number `seq`;
/// returns the output bytes (same length, encoding, step and byte order; row padding copied).
/// `bit_depth` gives the significant bits of 16-bit samples (default 16). Bad input (an
/// unsupported encoding, a Bayer frame of odd size, a short step or data) raises PerturbError
/// naming the field and its value.
#[pyfunction]
#[pyo3(
    signature = (data, encoding, width, height, step, id, severity, seed = Count(0),
        seq = Count(0), *, is_bigendian = 0, bit_depth = None),
    text_signature = "(data, encoding, width, height, step, id, severity, seed=0, seq=0, *, is_bigendian=0, bit_depth=None)"
)]
#[allow(clippy::too_many_arguments)]
pub fn apply_encoded<'py>(
    py: Python<'py>,
    data: &[u8],
    encoding: &str,
    width: u32,
    height: u32,
    step: usize,
    id: &str,
    severity: Severity,
    seed: Seed,
    seq: Seq,
    is_bigendian: u8,
    bit_depth: Option<u8>,
) -> PyResult<Bound<'py, PyBytes>> {
    let (spec, seq) = (spec(id, &severity, seed)?, seq.0);
    let mut view =
        EncodedView::from_ros(data, width, height, step, encoding, is_bigendian).map_err(perr)?;
    if let Some(bits) = bit_depth {
        view = view.with_bit_depth(bits).map_err(perr)?;
    }
    let mut p = CameraPerturber::from_spec(spec).map_err(perr)?;
    let out = detach(py, || {
        let mut out = vec![0u8; data.len()];
        p.apply_encoded(&view, &mut out, seq, &mut Scratch::new())
            .map(|()| out)
    })
    .map_err(perr)?;
    Ok(PyBytes::new(py, &out))
}
