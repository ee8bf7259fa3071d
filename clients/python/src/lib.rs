//! # perturb-python
//!
//! The compiled part of the Python package `perturb` (module `perturb._perturb`): perturb-core's
//! camera and LiDAR perturbers, the catalogue and the clustering detector on numpy arrays, and
//! the per-file batch worker of `perturb batch` for the package's Ray helpers. It is thin: every
//! result comes from the same core calls as `perturb apply` and the daemon, so the bytes are the
//! same for the same ID, severity, seed and sequence number.
//!
//! - Input arrays are read in place (no copy) when their pixels (or points) are packed; any row
//!   stride is fine for images. Other layouts (a channel-reversed view, a transposed array, a
//!   column slice of a cloud) are copied once into a contiguous array first.
//! - The GIL is released while a frame is perturbed. A perturber object can be shared by threads:
//!   each call takes a prepared perturber state from the object's pool (or builds one), so calls
//!   from several threads run in parallel and give the same bytes as calls in sequence.
//! - Errors raise `perturb.PerturbError` (a `ValueError`) with the core's message.
//!
//! Built with maturin (`pip install clients/python`), which sets `PYO3_BUILD_EXTENSION_MODULE`
//! so that the extension does not link libpython.

mod encoded;
mod report;

use numpy::{
    IxDyn, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use perturb_core::cloud::{Datatype, PointField, PointLayout};
use perturb_core::detector::{Detector, DetectorConfig, ObjectClass, points_in_boxes};
use perturb_core::image::{Image, ImageView, ImageViewMut, PixelFormat};
use perturb_core::lidar::Points;
use perturb_core::perturber::{self as core, Spec};
use perturb_core::registry::{self, CATALOGUE, Modality};
use perturb_core::sensor_model::SensorModel;
use perturb_study::batch::{self, BatchOptions, FileWorker, Selection, Set, Shard};
use perturb_study::dataset::Dataset;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyInt, PyList};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

create_exception!(
    _perturb,
    PerturbError,
    PyValueError,
    "A perturbation could not be configured or applied: unknown ID, bad severity, wrong dtype, \
     shape or layout of the input, unreadable file. The message is the core's."
);

/// A `PerturbError` carrying `e`'s message.
fn perr(e: impl std::fmt::Display) -> PyErr {
    PerturbError::new_err(e.to_string())
}

/// Locks `m`; a panic in another thread while it held the lock leaves the pool usable (it only
/// holds whole perturber states).
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// An integer argument `name` (a Python `int`, not a `bool`, a `float` or a `str`), or a
/// `PerturbError` naming the argument and what it got. Larger than any i128: `None` (out of the
/// range of every argument).
fn int_arg(obj: Borrowed<'_, '_, PyAny>, name: &str) -> PyResult<Option<i128>> {
    let is_int = obj.is_instance_of::<PyInt>() && !obj.is_instance_of::<PyBool>();
    if !is_int {
        return Err(perr(format!(
            "{name} must be an integer, got {} {}",
            type_name(&obj.to_owned()),
            repr(obj)
        )));
    }
    Ok(obj.extract::<i128>().ok())
}

/// `repr(obj)`, or `?`.
fn repr(obj: Borrowed<'_, '_, PyAny>) -> String {
    obj.repr().map_or_else(|_| "?".into(), |r| r.to_string())
}

/// A `seed` or `seq` argument: an integer in 0..2**64 (any other value raises `PerturbError`
/// naming the argument).
#[derive(Clone, Copy, Debug)]
struct Count<const SEQ: bool>(u64);

/// The `seed` argument.
type Seed = Count<false>;
/// The `seq` argument (frame sequence number).
type Seq = Count<true>;

impl<'a, 'py, const SEQ: bool> FromPyObject<'a, 'py> for Count<SEQ> {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        let name = if SEQ { "seq" } else { "seed" };
        let v = int_arg(obj, name)?;
        v.and_then(|v| u64::try_from(v).ok())
            .map(Count)
            .ok_or_else(|| {
                perr(format!(
                    "{name} must be an integer in 0..2**64, got {}",
                    repr(obj)
                ))
            })
    }
}

/// The `severity` argument: an integer, checked against the perturbation's range by [`spec`].
#[derive(Clone, Debug)]
struct Severity {
    value: Option<i128>,
    shown: String,
}

impl<'a, 'py> FromPyObject<'a, 'py> for Severity {
    type Error = PyErr;

    fn extract(obj: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        Ok(Severity {
            value: int_arg(obj, "severity")?,
            shown: repr(obj),
        })
    }
}

/// The perturbation of `id` at `severity` with `seed` (the severity checked against the range of
/// `id` without truncating it to a byte first).
fn spec(id: &str, severity: &Severity, seed: Seed) -> PyResult<Spec> {
    let entry = registry::find(id).map_err(perr)?;
    match severity.value.and_then(|s| u8::try_from(s).ok()) {
        Some(s) => Spec::new(entry.id, s, seed.0).map_err(perr),
        None => Err(perr(format!(
            "severity {} is out of range for {}: valid severities are 1..={}",
            severity.shown,
            entry.id,
            entry.max_severity()
        ))),
    }
}

/// The `severities` argument: a list of integers in 1..=255 (the selection then keeps those
/// each perturbation has).
fn severity_list(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<u8>> {
    let Some(o) = obj.filter(|o| !o.is_none()) else {
        return Ok(Vec::new());
    };
    let items = o.try_iter().map_err(|_| {
        perr(format!(
            "severities must be a list of integers, got {} {}",
            type_name(o),
            repr(o.as_borrowed())
        ))
    })?;
    items
        .map(|item| {
            let item = item?;
            int_arg(item.as_borrowed(), "severities")?
                .and_then(|v| u8::try_from(v).ok())
                .filter(|&v| v >= 1)
                .ok_or_else(|| {
                    perr(format!(
                        "severities: {} is not a severity (1..=5 for camera, 1..=3 for LiDAR)",
                        repr(item.as_borrowed())
                    ))
                })
        })
        .collect()
}

/// An optional `str` argument (None when absent or `None`).
fn opt_str(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<String>> {
    match obj {
        None => Ok(None),
        Some(o) if o.is_none() => Ok(None),
        Some(o) => o.extract::<String>().map(Some).map_err(|_| {
            perr(format!(
                "{name} must be a str, got {} {}",
                type_name(o),
                repr(o.as_borrowed())
            ))
        }),
    }
}

/// An optional number argument (an `int` or a `float`, not a `bool`).
fn opt_f32(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<f32>> {
    match obj {
        None => Ok(None),
        Some(o) if o.is_none() => Ok(None),
        Some(o) if !o.is_instance_of::<PyBool>() && o.extract::<f64>().is_ok() => {
            Ok(Some(o.extract::<f64>()? as f32))
        }
        Some(o) => Err(perr(format!(
            "{name} must be a number, got {} {}",
            type_name(o),
            repr(o.as_borrowed())
        ))),
    }
}

/// An optional list of `str` argument.
fn opt_strs(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Vec<String>>> {
    match obj {
        None => Ok(None),
        Some(o) if o.is_none() => Ok(None),
        Some(o) if !o.is_instance_of::<pyo3::types::PyString>() => {
            o.extract::<Vec<String>>().map(Some).map_err(|_| {
                perr(format!(
                    "{name} must be a list of str, got {} {}",
                    type_name(o),
                    repr(o.as_borrowed())
                ))
            })
        }
        Some(o) => Err(perr(format!(
            "{name} must be a list of str, got the str {}",
            repr(o.as_borrowed())
        ))),
    }
}

/// A `bool` argument.
fn flag(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<bool> {
    match obj {
        None => Ok(false),
        Some(o) => o.cast::<PyBool>().map(|b| b.is_true()).map_err(|_| {
            perr(format!(
                "{name} must be True or False, got {} {}",
                type_name(o),
                repr(o.as_borrowed())
            ))
        }),
    }
}

/// The type name of `obj`.
fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string())
}

/// `numpy.<name>(obj)`.
fn numpy_call<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    obj.py().import("numpy")?.call_method1(name, (obj,))
}

/// `obj` as a numpy array (numpy arrays as they are; anything else through `numpy.asarray`,
/// which does not copy a buffer it can share).
fn as_ndarray<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let a = numpy_call(obj, "asarray")?;
    a.cast_into::<PyUntypedArray>()
        .map_err(|e| perr(format!("cannot read the input as an array: {e}")))
}

fn shape_text(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

fn dtype_text(a: &Bound<'_, PyUntypedArray>) -> String {
    a.dtype()
        .str()
        .map(|s| s.to_string())
        .unwrap_or_else(|_| "?".into())
}

// ------------------------------------------------------------------------------------------
// Images

/// The layout of an image array: geometry, row stride, and whether it can be read in place.
#[derive(Clone, Copy, Debug)]
struct ImageLayout {
    width: u32,
    height: u32,
    channels: usize,
    format: PixelFormat,
    /// Bytes from one row to the next (valid when `packed`).
    stride: usize,
    /// Pixels of a row are adjacent and channels interleaved (any positive row stride).
    packed: bool,
}

impl ImageLayout {
    /// The bytes the image spans from its first pixel.
    fn span(&self) -> usize {
        if self.height == 0 || self.width == 0 {
            0
        } else {
            (self.height as usize - 1) * self.stride + self.width as usize * self.channels
        }
    }
}

/// Reads the layout of a uint8 image array; `format` overrides the pixel format of 3- and
/// 4-channel arrays (rgb8, bgr8, rgba8, bgra8).
fn image_layout(a: &Bound<'_, PyUntypedArray>, format: Option<&str>) -> PyResult<ImageLayout> {
    let shape = a.shape();
    let expected = "expected an HxWx3 (rgb8), HxWx4 (rgba8) or HxW (mono8) uint8 array";
    if !a.dtype().is_equiv_to(&numpy::dtype::<u8>(a.py())) {
        return Err(perr(format!(
            "{expected}, got dtype {} (convert with .astype(numpy.uint8))",
            dtype_text(a)
        )));
    }
    let (h, w, c) = match *shape {
        [h, w] => (h, w, 1),
        [h, w, c] if matches!(c, 1 | 3 | 4) => (h, w, c),
        _ => {
            return Err(perr(format!("{expected}, got shape {}", shape_text(shape))));
        }
    };
    let fmt = match (c, format) {
        (1, None) => PixelFormat::Mono8,
        (3, None) => PixelFormat::Rgb8,
        (4, None) => PixelFormat::Rgba8,
        (_, Some(f)) => {
            let f: PixelFormat = f.parse().map_err(perr)?;
            if f.channels() != c {
                return Err(perr(format!(
                    "format {f} has {} channels but the array has {c} (shape {})",
                    f.channels(),
                    shape_text(shape)
                )));
            }
            f
        }
        _ => unreachable!("channels checked above"),
    };
    let too_large = |d: usize| u32::try_from(d).map_err(|_| perr("image dimension too large"));
    let strides = a.strides();
    let row = w * c;
    let (s0, s1, s2) = (
        strides[0],
        strides[1],
        if shape.len() == 3 { strides[2] } else { 1 },
    );
    let packed = (w <= 1 || s1 == c as isize)
        && (c == 1 || s2 == 1)
        && (h <= 1 || (s0 > 0 && s0 as usize >= row));
    Ok(ImageLayout {
        width: too_large(w)?,
        height: too_large(h)?,
        channels: c,
        format: fmt,
        stride: if h > 1 { s0 as usize } else { row },
        packed,
    })
}

/// An image array borrowed for reading, with its layout. Non-packed arrays were copied into a
/// contiguous one first (`copied`).
struct ImageIn<'py> {
    array: PyReadonlyArrayDyn<'py, u8>,
    layout: ImageLayout,
    copied: bool,
}

impl ImageIn<'_> {
    /// The pixels, borrowed from the array.
    // numpy arrays: uninitialised output arrays and their slices.
    #[allow(unsafe_code)]
    fn bytes(&self) -> &[u8] {
        let n = self.layout.span();
        if n == 0 {
            return &[];
        }
        // SAFETY: the read-only borrow `array` keeps the array alive and registered as borrowed
        // for as long as `self` lives; the layout check made sure its memory holds `n` bytes from
        // the data pointer (positive row stride, packed rows).
        unsafe { std::slice::from_raw_parts(self.array.as_array_ptr_data(), n) }
    }

    fn view(&self) -> PyResult<ImageView<'_>> {
        let l = self.layout;
        ImageView::new(self.bytes(), l.width, l.height, l.stride, l.format).map_err(perr)
    }
}

/// Reads an image argument, copying it only if its pixels are not packed.
fn image_in<'py>(obj: &Bound<'py, PyAny>, format: Option<&str>) -> PyResult<ImageIn<'py>> {
    let a = as_ndarray(obj)?;
    let mut layout = image_layout(&a, format)?;
    let (a, copied) = if layout.packed {
        (a, false)
    } else {
        let c = numpy_call(a.as_any(), "ascontiguousarray")?.cast_into::<PyUntypedArray>()?;
        layout = image_layout(&c, format)?;
        (c, true)
    };
    let array = a
        .cast::<PyArrayDyn<u8>>()?
        .try_readonly()
        .map_err(|e| perr(format!("the image is being written elsewhere: {e}")))?;
    Ok(ImageIn {
        array,
        layout,
        copied,
    })
}

/// Raw access helpers on numpy's borrow types.
trait DataPtr {
    fn as_array_ptr_data(&self) -> *const u8;
}

impl DataPtr for PyReadonlyArrayDyn<'_, u8> {
    fn as_array_ptr_data(&self) -> *const u8 {
        self.as_array().as_ptr()
    }
}

/// Runs `f` with the GIL released. When the process may use one core (rayon's pool has one
/// thread, as under `taskset -c 0`), `f` runs on the calling thread itself, made the only worker
/// of a pool of its own, so the perturbation's parallel loops run inline instead of being handed
/// to the pool's thread and waited for (a hand-off per loop, which costs the cheap perturbations
/// a large share of their time). With more cores, `f` uses the global pool.
fn detach<R: Send>(py: Python<'_>, f: impl FnOnce() -> R + Send) -> R {
    py.detach(|| {
        if rayon::current_num_threads() > 1 {
            return f();
        }
        thread_local! {
            static INLINE: Option<rayon::ThreadPool> = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .use_current_thread()
                .build()
                .ok();
        }
        INLINE.with(|pool| match pool {
            Some(pool) => pool.install(f),
            None => f(),
        })
    })
}

/// A pool of prepared perturber states shared by the threads that call one Python object.
struct Pool<T> {
    free: Mutex<Vec<T>>,
}

impl<T> Pool<T> {
    fn new() -> Self {
        Pool {
            free: Mutex::new(Vec::new()),
        }
    }

    /// Runs `f` on a free state (or a new one from `make`), then returns the state to the pool.
    fn with<R>(
        &self,
        make: impl FnOnce() -> perturb_core::Result<T>,
        f: impl FnOnce(&mut T) -> R,
    ) -> PyResult<R> {
        let popped = lock(&self.free).pop();
        let mut state = match popped {
            Some(s) => s,
            None => make().map_err(perr)?,
        };
        let r = f(&mut state);
        lock(&self.free).push(state);
        Ok(r)
    }
}

/// A camera perturbation configured by ID (or name), severity and seed.
///
/// `p(image, seq=0)` returns the perturbed copy of an HxWx3 (rgb8), HxWx4 (rgba8) or HxW
/// (mono8) uint8 array; `p.apply_(image, seq=0)` perturbs it in place. The output is a pure
/// function of (image, ID, severity, seed, seq), byte-identical to `perturb apply` and the
/// daemon. Safe to call from many threads; the GIL is released during the work.
#[pyclass(module = "perturb._perturb", frozen, subclass)]
struct CameraPerturber {
    spec: Spec,
    pool: Pool<core::CameraPerturber>,
}

#[pymethods]
impl CameraPerturber {
    #[new]
    #[pyo3(signature = (id, severity, seed = Count(0)), text_signature = "(id, severity, seed=0)")]
    fn new(id: &str, severity: Severity, seed: Seed) -> PyResult<Self> {
        let spec = spec(id, &severity, seed)?;
        // Validates the modality now rather than on the first frame.
        let first = core::CameraPerturber::from_spec(spec).map_err(perr)?;
        let pool = Pool::new();
        lock(&pool.free).push(first);
        Ok(CameraPerturber { spec, pool })
    }

    /// Returns the perturbed copy of `image` (frame sequence number `seq`). `format` names the
    /// pixel order of a 3- or 4-channel array (`rgb8` default, `bgr8` for OpenCV images,
    /// `rgba8`, `bgra8`).
    #[pyo3(signature = (image, seq = Count(0), *, format = None))]
    // numpy arrays: uninitialised output arrays and their slices.
    #[allow(unsafe_code)]
    fn __call__<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        seq: Seq,
        format: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<u8>>> {
        let format = opt_str(format, "format")?;
        let (seq, format) = (seq.0, format.as_deref());
        let input = image_in(image, format)?;
        let shape = input.array.shape().to_vec();
        // Not zeroed: every perturbation writes every byte of its output (the camera contract),
        // and zeroing a fresh frame costs as much as the cheapest perturbations.
        // SAFETY: the array is fully written below before Python can see it.
        let out = unsafe { PyArrayDyn::<u8>::new(py, IxDyn(&shape), false) };
        {
            let mut guard = out.try_readwrite().map_err(perr)?;
            let dst = guard.as_slice_mut().map_err(perr)?;
            let view = input.view()?;
            let l = input.layout;
            let spec = self.spec;
            detach(py, || {
                let mut o = ImageViewMut::new(
                    dst,
                    l.width,
                    l.height,
                    l.width as usize * l.channels,
                    l.format,
                )
                .map_err(perr)?;
                self.pool
                    .with(
                        || core::CameraPerturber::from_spec(spec),
                        |p| p.apply(&view, &mut o, seq),
                    )?
                    .map_err(perr)
            })?;
        }
        Ok(out)
    }

    /// Perturbs `image` in place (it must be writable) and returns it. The frame is perturbed
    /// into a scratch buffer and copied back (one copy of the frame).
    #[pyo3(
        signature = (image, seq = Count(0), *, format = None),
        text_signature = "(self, image, seq=0, *, format=None)"
    )]
    // numpy arrays: uninitialised output arrays and their slices.
    #[allow(unsafe_code)]
    fn apply_<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        seq: Seq,
        format: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let format_arg = format;
        let format = opt_str(format, "format")?;
        let format = format.as_deref();
        let a = image
            .cast::<PyUntypedArray>()
            .map_err(|_| perr("apply_ perturbs a numpy array in place; got another object"))?;
        let layout = image_layout(a, format)?;
        let spec = self.spec;
        if !layout.packed {
            // Strides the core cannot address: perturb a contiguous copy and assign it back.
            let out = self.__call__(py, image, seq, format_arg)?;
            image.set_item(pyo3::types::PyEllipsis::get(py), out)?;
            return Ok(image.clone());
        }
        let typed = a.cast::<PyArrayDyn<u8>>()?;
        let guard = typed
            .try_readwrite()
            .map_err(|e| perr(format!("the image is not writable here: {e}")))?;
        let n = layout.span();
        if n == 0 {
            return Ok(image.clone());
        }
        // SAFETY: the read-write borrow `guard` keeps the array alive and exclusively borrowed
        // until the end of this function; the layout check made sure it spans `n` bytes.
        let data: &mut [u8] =
            unsafe { std::slice::from_raw_parts_mut(guard.as_array().as_ptr() as *mut u8, n) };
        let l = layout;
        detach(py, || {
            let mut scratch = Image::new(l.width, l.height, l.format);
            {
                let view =
                    ImageView::new(&*data, l.width, l.height, l.stride, l.format).map_err(perr)?;
                self.pool
                    .with(
                        || core::CameraPerturber::from_spec(spec),
                        |p| p.apply(&view, &mut scratch.view_mut(), seq.0),
                    )?
                    .map_err(perr)?;
            }
            ImageViewMut::new(data, l.width, l.height, l.stride, l.format)
                .and_then(|mut o| o.copy_from(&scratch.view()))
                .map_err(perr)
        })?;
        drop(guard);
        Ok(image.clone())
    }

    /// The perturbation's ID (`C-C7`).
    #[getter]
    fn id(&self) -> &'static str {
        self.spec.entry.id
    }

    /// The perturbation's name (`rain`).
    #[getter]
    fn name(&self) -> &'static str {
        self.spec.entry.name
    }

    /// The severity.
    #[getter]
    fn severity(&self) -> u8 {
        self.spec.severity
    }

    /// The seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.spec.seed
    }

    fn __repr__(&self) -> String {
        format!(
            "CameraPerturber('{}', {}, seed={})  # {}",
            self.spec.entry.id, self.spec.severity, self.spec.seed, self.spec.entry.name
        )
    }
}

// ------------------------------------------------------------------------------------------
// Point clouds

/// The point layout of an (N, k) float32 array with the given column names.
fn cloud_layout(names: &[String]) -> PyResult<Arc<PointLayout>> {
    let fields = names
        .iter()
        .enumerate()
        .map(|(i, n)| PointField::new(n, 4 * i as u32, Datatype::Float32))
        .collect();
    Ok(Arc::new(
        PointLayout::new(fields, 4 * names.len() as u32, false).map_err(perr)?,
    ))
}

/// The column names: `fields` if given, else x, y, z, intensity, then c4, c5, ...
fn column_names(fields: Option<&[String]>, k: usize) -> PyResult<Vec<String>> {
    match fields {
        Some(f) if f.len() != k => Err(perr(format!(
            "fields names {} columns but the array has {k}",
            f.len()
        ))),
        Some(f) => Ok(f.to_vec()),
        None => Ok((0..k)
            .map(|i| match i {
                0 => "x".to_string(),
                1 => "y".to_string(),
                2 => "z".to_string(),
                3 => "intensity".to_string(),
                _ => format!("c{i}"),
            })
            .collect()),
    }
}

/// A point-cloud array borrowed for reading (C-contiguous; other layouts were copied first).
struct CloudIn<'py> {
    array: PyReadonlyArrayDyn<'py, f32>,
    n: usize,
    k: usize,
    copied: bool,
}

impl CloudIn<'_> {
    // numpy arrays: uninitialised output arrays and their slices.
    #[allow(unsafe_code)]
    fn bytes(&self) -> &[u8] {
        let len = self.n * self.k * 4;
        if len == 0 {
            return &[];
        }
        // SAFETY: the array is C-contiguous float32 of n x k values, kept alive and borrowed
        // read-only by `array` while `self` lives; u8 has no alignment requirement.
        unsafe { std::slice::from_raw_parts(self.array.as_array().as_ptr() as *const u8, len) }
    }
}

/// Reads an (N, k) float32 cloud argument (k >= 3), copying it only if it is not C-contiguous.
fn cloud_in<'py>(obj: &Bound<'py, PyAny>) -> PyResult<CloudIn<'py>> {
    let a = as_ndarray(obj)?;
    let expected = "expected an (N, k) float32 array: x, y, z, intensity, then any extra columns";
    if !a.dtype().is_equiv_to(&numpy::dtype::<f32>(a.py())) {
        return Err(perr(format!(
            "{expected}; got dtype {} (convert with .astype(numpy.float32))",
            dtype_text(&a)
        )));
    }
    let (n, k) = match *a.shape() {
        [n, k] if k >= 3 => (n, k),
        _ => {
            return Err(perr(format!(
                "{expected}; got shape {}",
                shape_text(a.shape())
            )));
        }
    };
    let (a, copied) = if a.is_c_contiguous() {
        (a, false)
    } else {
        let c = numpy_call(a.as_any(), "ascontiguousarray")?.cast_into::<PyUntypedArray>()?;
        (c, true)
    };
    let array = a
        .cast::<PyArrayDyn<f32>>()?
        .try_readonly()
        .map_err(|e| perr(format!("the cloud is being written elsewhere: {e}")))?;
    Ok(CloudIn {
        array,
        n,
        k,
        copied,
    })
}

/// The cloud view of `bytes` (`n` points of `layout`), dense if every value is finite (as the
/// KITTI reader decides).
fn cloud_view<'a>(
    layout: &Arc<PointLayout>,
    bytes: &'a [u8],
    n: usize,
) -> PyResult<perturb_core::cloud::CloudView<'a>> {
    let dense = bytes
        .chunks_exact(4)
        .all(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]).is_finite());
    let width = u32::try_from(n).map_err(|_| perr("too many points"))?;
    perturb_core::cloud::CloudView::new(
        layout.clone(),
        bytes,
        width,
        1,
        n * layout.point_step as usize,
        dense,
    )
    .map_err(perr)
}

/// The sensor model from a name, a forward axis and an intensity scale, as `perturb apply` reads
/// them for a cloud of `kind` (`None`: an array, read like a file of no known kind: VLP-32C, x
/// forward).
fn sensor_model(
    kind: Option<perturb_core::formats::FileKind>,
    sensor: Option<&Bound<'_, PyAny>>,
    forward: Option<&Bound<'_, PyAny>>,
    intensity_max: Option<&Bound<'_, PyAny>>,
) -> PyResult<SensorModel> {
    let sensor = opt_str(sensor, "sensor")?;
    let forward = opt_str(forward, "forward")?;
    let intensity_max = opt_f32(intensity_max, "intensity_max")?;
    if let Some(f) = &forward {
        use perturb_core::sensor_model::{Axes, Axis};
        Axis::parse(f)
            .and_then(|a| Axes::new(a, Axis::PosZ))
            .map_err(|e| perr(format!("forward: {e}")))?;
    }
    perturb_study::files::sensor_for(kind, sensor.as_deref(), forward.as_deref(), intensity_max)
        .map_err(perr)
}

/// A LiDAR perturbation configured by ID (or name), severity, seed and sensor model.
///
/// `p(points, seq=0)` returns the perturbed copy of an (N, k) float32 array (x, y, z, intensity,
/// then extra columns, carried through). Points may be removed or added: the output has N' rows.
/// `sensor` is the LiDAR model (vlp32c by default, vlp16, hdl32e, hdl64e: KITTI is hdl64e),
/// `intensity_max` its intensity scale (1 or 255) and `forward` the axis its frame looks along
/// (`+x` by default as in ROS and KITTI; `+y` for nuScenes' LIDAR_TOP): every direction-dependent
/// perturbation (the field of view, shifts, motion, object boxes) works in the vehicle's frame.
/// `fields` names the columns (default x, y, z, intensity, c4, ...; name a column `ring` to give
/// the laser index, as in nuScenes `.pcd.bin`).
#[pyclass(module = "perturb._perturb", frozen, subclass)]
struct LidarPerturber {
    spec: Spec,
    sensor: SensorModel,
    fields: Option<Vec<String>>,
    pool: Pool<core::LidarPerturber>,
}

#[pymethods]
impl LidarPerturber {
    #[new]
    #[pyo3(
        signature = (id, severity, seed = Count(0), sensor = None, intensity_max = None, *, fields = None, forward = None),
        text_signature = "(id, severity, seed=0, sensor=None, intensity_max=None, *, fields=None, forward=None)"
    )]
    fn new(
        id: &str,
        severity: Severity,
        seed: Seed,
        sensor: Option<&Bound<'_, PyAny>>,
        intensity_max: Option<&Bound<'_, PyAny>>,
        fields: Option<&Bound<'_, PyAny>>,
        forward: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let spec = spec(id, &severity, seed)?;
        let sensor = sensor_model(None, sensor, forward, intensity_max)?;
        let fields = opt_strs(fields, "fields")?;
        let first = core::LidarPerturber::from_spec(spec, sensor.clone()).map_err(perr)?;
        let pool = Pool::new();
        lock(&pool.free).push(first);
        Ok(LidarPerturber {
            spec,
            sensor,
            fields,
            pool,
        })
    }

    /// Returns the perturbed copy of `points` (frame sequence number `seq`).
    #[pyo3(signature = (points, seq = Count(0)))]
    // numpy arrays: uninitialised output arrays and their slices.
    #[allow(unsafe_code)]
    fn __call__<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        seq: Seq,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let seq = seq.0;
        let input = cloud_in(points)?;
        let layout = cloud_layout(&column_names(self.fields.as_deref(), input.k)?)?;
        let view = cloud_view(&layout, input.bytes(), input.n)?;
        let (spec, k) = (self.spec, input.k);
        let make = || core::LidarPerturber::from_spec(spec, self.sensor.clone());
        let popped = lock(&self.pool.free).pop();
        let mut state = match popped {
            Some(s) => s,
            None => make().map_err(perr)?,
        };
        let result = (|| {
            let bytes = detach(py, || state.plan(&view, seq, None)).map_err(perr)?;
            let rows = bytes / (4 * k);
            let out = PyArrayDyn::<f32>::zeros(py, IxDyn(&[rows, k]), false);
            {
                let mut guard = out.try_readwrite().map_err(perr)?;
                let dst = guard.as_slice_mut().map_err(perr)?;
                // SAFETY: f32 memory viewed as bytes (no alignment needed, every byte pattern
                // is a valid f32).
                let dst: &mut [u8] = unsafe {
                    std::slice::from_raw_parts_mut(dst.as_mut_ptr() as *mut u8, dst.len() * 4)
                };
                let st = &state;
                detach(py, || st.write_planned(&view, dst)).map_err(perr)?;
            }
            Ok(out)
        })();
        lock(&self.pool.free).push(state);
        result
    }

    /// The perturbation's ID (`L-A9`).
    #[getter]
    fn id(&self) -> &'static str {
        self.spec.entry.id
    }

    /// The perturbation's name (`fog_fast`).
    #[getter]
    fn name(&self) -> &'static str {
        self.spec.entry.name
    }

    /// The severity.
    #[getter]
    fn severity(&self) -> u8 {
        self.spec.severity
    }

    /// The seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.spec.seed
    }

    /// The sensor model's name.
    #[getter]
    fn sensor(&self) -> &'static str {
        self.sensor.name
    }

    /// The axis the sensor's frame looks along (`+x`, `-x`, `+y` or `-y`).
    #[getter]
    fn forward(&self) -> String {
        self.sensor.axes.forward.to_string()
    }

    /// The intensity full scale (1 or 255).
    #[getter]
    fn intensity_max(&self) -> f32 {
        self.sensor.intensity_max
    }

    fn __repr__(&self) -> String {
        format!(
            "LidarPerturber('{}', {}, seed={}, sensor='{}', forward='{}')  # {}",
            self.spec.entry.id,
            self.spec.severity,
            self.spec.seed,
            self.sensor.name,
            self.sensor.axes.forward,
            self.spec.entry.name
        )
    }
}

/// The clustering detector's boxes on `points` (an (N, k) float32 array), as `perturb detect
/// --json` prints them: a list of dicts with `center` (x, y, z), `size` (length, width, height),
/// `yaw` (radians about +z), `class` (`vehicle`, `pedestrian` or `other`) and `points` (scan
/// points inside the box), in the cloud's own frame. `sensor`, `forward` and `intensity_max` say
/// how to read the cloud, as for `LidarPerturber` (the detector works in the vehicle's frame and
/// takes its clustering radii from the sensor's beam spacing). `objects=True` keeps only road
/// users (`perturb detect --objects`); `class_="vehicle"` only one class (`--class`).
#[pyfunction]
#[pyo3(
    signature = (points, *, objects = None, fields = None, sensor = None, forward = None,
        intensity_max = None, class_ = None),
    text_signature = "(points, *, objects=False, fields=None, sensor=None, forward=None, intensity_max=None, class_=None)"
)]
#[allow(clippy::too_many_arguments)]
fn detect<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    objects: Option<&Bound<'py, PyAny>>,
    fields: Option<&Bound<'py, PyAny>>,
    sensor: Option<&Bound<'py, PyAny>>,
    forward: Option<&Bound<'py, PyAny>>,
    intensity_max: Option<&Bound<'py, PyAny>>,
    class_: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let objects = flag(objects, "objects")?;
    let fields = opt_strs(fields, "fields")?;
    let sensor = sensor_model(None, sensor, forward, intensity_max)?;
    let config = match opt_str(class_, "class_")? {
        Some(c) => {
            DetectorConfig::only(ObjectClass::parse(&c).map_err(|e| perr(format!("class_: {e}")))?)
        }
        None if objects => DetectorConfig::objects(),
        None => DetectorConfig::default(),
    };
    let input = cloud_in(points)?;
    let layout = cloud_layout(&column_names(fields.as_deref(), input.k)?)?;
    let view = cloud_view(&layout, input.bytes(), input.n)?;
    let (found, counts) = detach(py, || -> perturb_core::Result<_> {
        let p = Points::extract(&view, &sensor, false)?;
        let found = Detector::new(config).detect_classified(&p);
        let boxes: Vec<_> = found.iter().map(|d| d.bbox).collect();
        let counts = points_in_boxes(&p, &boxes);
        Ok((found, counts))
    })
    .map_err(perr)?;
    let out = PyList::empty(py);
    for (d, n) in found.iter().zip(counts) {
        // In the cloud's own frame, as `perturb detect` prints them.
        let b = d.bbox.to_sensor(&sensor.axes);
        let o = PyDict::new(py);
        o.set_item("center", (b.center[0], b.center[1], b.center[2]))?;
        o.set_item("size", (b.size[0], b.size[1], b.size[2]))?;
        o.set_item("yaw", b.yaw)?;
        o.set_item("class", d.class.as_str())?;
        o.set_item("points", n)?;
        out.append(o)?;
    }
    Ok(out)
}

/// Every perturbation of the catalogue: a list of dicts with `id`, `name`, `modality`
/// (`camera` or `lidar`), `family`, `severities` (list), `description` and `reference`.
#[pyfunction]
#[pyo3(signature = (modality = None))]
fn catalogue<'py>(py: Python<'py>, modality: Option<&str>) -> PyResult<Bound<'py, PyList>> {
    let only: Option<Modality> = modality.map(|m| m.parse()).transpose().map_err(perr)?;
    let out = PyList::empty(py);
    for e in CATALOGUE
        .iter()
        .filter(|e| only.is_none_or(|m| e.modality == m))
    {
        let d = PyDict::new(py);
        d.set_item("id", e.id)?;
        d.set_item("name", e.name)?;
        d.set_item("modality", e.modality.as_str())?;
        d.set_item("family", e.family)?;
        // As ints (a Vec<u8> would become `bytes`).
        d.set_item(
            "severities",
            e.severities().map(u32::from).collect::<Vec<u32>>(),
        )?;
        d.set_item("description", e.description)?;
        d.set_item("reference", e.reference)?;
        out.append(d)?;
    }
    Ok(out)
}

/// Whether the last call read its input in place: used by the tests of the no-copy path.
/// Returns (copied, layout) for an image array: `copied` is True when the array's strides make
/// the package copy it first.
#[pyfunction]
#[pyo3(signature = (array, *, cloud = false))]
fn input_is_copied(array: &Bound<'_, PyAny>, cloud: bool) -> PyResult<bool> {
    Ok(if cloud {
        cloud_in(array)?.copied
    } else {
        image_in(array, None)?.copied
    })
}

// ------------------------------------------------------------------------------------------
// Batch (the Ray helpers)

/// Plans a batch as `perturb batch` does and writes its manifest `OUT/batch.json`: returns a
/// dict with `root`, `files` (paths relative to root, in the order that gives each its sequence
/// number), `modality`, `sets` and `todo` (lists of (id, severity, directory)). Only folders of
/// images or point clouds (a bag goes through `perturb batch`).
#[pyfunction]
#[pyo3(
    signature = (input, out, *, ids = None, families = None, modality = None,
        severities = None, seed = Count(0), sensor = None, intensity_max = None, shard = None,
        forward = None),
    text_signature = "(input, out, *, ids=None, families=None, modality=None, severities=None, seed=0, sensor=None, intensity_max=None, shard=None, forward=None)"
)]
#[allow(clippy::too_many_arguments)]
fn plan_batch<'py>(
    py: Python<'py>,
    input: PathBuf,
    out: PathBuf,
    ids: Option<&Bound<'py, PyAny>>,
    families: Option<&Bound<'py, PyAny>>,
    modality: Option<&Bound<'py, PyAny>>,
    severities: Option<&Bound<'py, PyAny>>,
    seed: Seed,
    sensor: Option<&Bound<'py, PyAny>>,
    intensity_max: Option<&Bound<'py, PyAny>>,
    shard: Option<&Bound<'py, PyAny>>,
    forward: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let ids = opt_strs(ids, "ids")?.unwrap_or_default();
    let families = opt_strs(families, "families")?.unwrap_or_default();
    let modality = opt_str(modality, "modality")?;
    let severities = severity_list(severities)?;
    let (seed, sensor) = (seed.0, opt_str(sensor, "sensor")?);
    let forward = opt_str(forward, "forward")?;
    let intensity_max = opt_f32(intensity_max, "intensity_max")?;
    let shard = opt_str(shard, "shard")?;
    // Checked now, with the input kind's defaults, as `perturb batch` checks them.
    perturb_study::files::sensor_for(None, sensor.as_deref(), forward.as_deref(), intensity_max)
        .map_err(perr)?;
    let opts = BatchOptions {
        input: input.clone(),
        out: out.clone(),
        selection: Selection {
            ids,
            families,
            modality: modality.map(|m| m.parse()).transpose().map_err(perr)?,
            severities,
        },
        seed,
        sensor,
        forward,
        intensity_max,
        topics: Vec::new(),
        lidar_metrics: false,
        shard: shard
            .map(|s| s.parse::<Shard>())
            .transpose()
            .map_err(perr)?,
        compression: None,
    };
    if let Ok(Dataset::Bag(_)) = Dataset::open(&input) {
        return Err(perr(format!(
            "{} is a bag: the Ray batch takes a folder of images or point clouds; use `perturb batch` (with --shard i/n over machines) for bags",
            input.display()
        )));
    }
    let planned = py
        .detach(|| batch::plan(&opts, &perturb_study::Silent))
        .map_err(perr)?;
    let Dataset::Files {
        root,
        files,
        modality,
    } = &planned.dataset
    else {
        unreachable!("bags refused above")
    };
    let sets = |s: &[Set]| -> Vec<(String, u8, String)> {
        s.iter()
            .map(|s| {
                (
                    s.entry.id.to_string(),
                    s.severity,
                    s.dir(&out).display().to_string(),
                )
            })
            .collect()
    };
    let d = PyDict::new(py);
    d.set_item("root", root.display().to_string())?;
    d.set_item(
        "files",
        files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>(),
    )?;
    d.set_item("modality", modality.as_str())?;
    d.set_item("sets", sets(&planned.sets))?;
    d.set_item("todo", sets(&planned.todo))?;
    Ok(d)
}

/// Marks a set directory finished (`.done` with its number of files), as `perturb batch` does.
#[pyfunction]
fn mark_done(dir: PathBuf, files: usize) -> PyResult<()> {
    batch::mark_done(&dir, files).map_err(perr)
}

/// The per-file worker of `perturb batch` for one Ray actor: keeps one perturber per (ID,
/// severity) it meets, reads each file, perturbs it and writes it into its set's folder in the
/// input's format (skipping files already written), exactly as `perturb batch` does.
#[pyclass(module = "perturb._perturb", frozen)]
struct BatchWorker {
    root: PathBuf,
    seed: u64,
    sensor: Option<SensorModel>,
    workers: Mutex<HashMap<(String, u8), FileWorker>>,
}

#[pymethods]
impl BatchWorker {
    /// `root` is the dataset folder, `first_file` its first file (relative; it decides the default
    /// sensor model of point clouds as in `perturb batch`).
    #[new]
    #[pyo3(
        signature = (root, first_file, seed = Count(0), sensor = None, intensity_max = None,
            forward = None),
        text_signature = "(root, first_file, seed=0, sensor=None, intensity_max=None, forward=None)"
    )]
    fn new(
        root: PathBuf,
        first_file: PathBuf,
        seed: Seed,
        sensor: Option<&Bound<'_, PyAny>>,
        intensity_max: Option<&Bound<'_, PyAny>>,
        forward: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let kind = perturb_core::formats::FileKind::from_path(&first_file).map_err(perr)?;
        let sensor = if kind.is_image() {
            None
        } else {
            Some(sensor_model(Some(kind), sensor, forward, intensity_max)?)
        };
        Ok(BatchWorker {
            root,
            seed: seed.0,
            sensor,
            workers: Mutex::new(HashMap::new()),
        })
    }

    /// Perturbs file `rel` (sequence number `seq`) with (`id`, `severity`) into `dir/rel`;
    /// returns False if that file existed already.
    fn run(
        &self,
        py: Python<'_>,
        rel: PathBuf,
        seq: u64,
        id: &str,
        severity: u8,
        dir: PathBuf,
    ) -> PyResult<bool> {
        let key = (id.to_string(), severity);
        py.detach(|| {
            let mut map = lock(&self.workers);
            let worker = match map.entry(key) {
                std::collections::hash_map::Entry::Occupied(o) => o.into_mut(),
                std::collections::hash_map::Entry::Vacant(v) => {
                    let entry = registry::find_with_severity(id, severity).map_err(perr)?;
                    let set = Set { entry, severity };
                    v.insert(FileWorker::new(set, self.seed, self.sensor.as_ref()).map_err(perr)?)
                }
            };
            worker
                .run(&self.root, Path::new(&rel), &dir, seq)
                .map_err(perr)
        })
    }
}

/// The compiled module of the `perturb` package.
#[pymodule]
fn _perturb(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("PerturbError", m.py().get_type::<PerturbError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<CameraPerturber>()?;
    m.add_class::<LidarPerturber>()?;
    m.add_class::<BatchWorker>()?;
    m.add_function(wrap_pyfunction!(catalogue, m)?)?;
    m.add_function(wrap_pyfunction!(detect, m)?)?;
    m.add_function(wrap_pyfunction!(input_is_copied, m)?)?;
    m.add_function(wrap_pyfunction!(plan_batch, m)?)?;
    m.add_function(wrap_pyfunction!(mark_done, m)?)?;
    m.add_function(wrap_pyfunction!(report::report, m)?)?;
    m.add_function(wrap_pyfunction!(encoded::encodings, m)?)?;
    m.add_function(wrap_pyfunction!(encoded::apply_encoded, m)?)?;
    Ok(())
}
