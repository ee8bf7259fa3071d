//! The one entry point every user of the core goes through: configure a perturbation by ID,
//! severity and seed, then apply it frame after frame.
//!
//! [`CameraPerturber`] builds its state for the frame geometry on the first frame and rebuilds it
//! only when the geometry changes. [`LidarPerturber`] keeps its scratch arrays between clouds. Both
//! validate their inputs and outputs and return clear errors instead of panicking.
//!
//! ```
//! use perturb_core::image::{Image, PixelFormat};
//! use perturb_core::perturber::CameraPerturber;
//! let mut p = CameraPerturber::new("C-A1", 3, 42).unwrap();
//! let input = Image::new(64, 48, PixelFormat::Rgb8);
//! let a = p.apply_owned(&input.view(), 7).unwrap();
//! let b = p.apply_owned(&input.view(), 7).unwrap();
//! assert_eq!(a, b); // same seed and sequence number, same bytes
//! ```

use crate::camera::{CameraPerturbation, CameraSetup};
use crate::cloud::{Cloud, CloudView};
use crate::detector::{Detector, DetectorConfig};
use crate::encoding::{EncodedView, Scratch};
use crate::error::{Error, Result};
use crate::image::{Image, ImageGeometry, ImageView, ImageViewMut};
use crate::lidar::points::CloudShape;
use crate::lidar::{Box3, LidarFrame, LidarPerturbation, LidarSetup, Plan, Points};
use crate::registry::{self, Builder, Entry, Modality};
use crate::sensor_model::SensorModel;

/// Which perturbation, how strong, and the seed: everything that determines the output besides the
/// input and the sequence number.
#[derive(Clone, Copy, Debug)]
pub struct Spec {
    /// The catalogue entry.
    pub entry: &'static Entry,
    /// Severity within the entry's range.
    pub severity: u8,
    /// Seed.
    pub seed: u64,
}

impl PartialEq for Spec {
    fn eq(&self, other: &Self) -> bool {
        self.entry.id == other.entry.id
            && self.severity == other.severity
            && self.seed == other.seed
    }
}

impl Eq for Spec {}

impl Spec {
    /// Looks up `id` (ID or name) and validates the severity.
    pub fn new(id: &str, severity: u8, seed: u64) -> Result<Self> {
        Ok(Spec {
            entry: registry::find_with_severity(id, severity)?,
            severity,
            seed,
        })
    }
}

fn wrong_modality(entry: &'static Entry, found: &'static str) -> Error {
    Error::WrongModality {
        id: entry.id,
        expected: entry.modality.as_str(),
        found,
    }
}

/// A camera perturbation configured by ID, severity and seed.
pub struct CameraPerturber {
    spec: Spec,
    built: Option<(ImageGeometry, Box<dyn CameraPerturbation>)>,
}

impl std::fmt::Debug for CameraPerturber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CameraPerturber")
            .field("spec", &self.spec)
            .finish()
    }
}

impl CameraPerturber {
    /// Validates the ID (must be a camera perturbation) and the severity.
    pub fn new(id: &str, severity: u8, seed: u64) -> Result<Self> {
        Self::from_spec(Spec::new(id, severity, seed)?)
    }

    /// Like [`CameraPerturber::new`] from a [`Spec`].
    pub fn from_spec(spec: Spec) -> Result<Self> {
        match spec.entry.build {
            Builder::Camera(_) => Ok(CameraPerturber { spec, built: None }),
            Builder::Lidar(_) => Err(wrong_modality(spec.entry, "image")),
        }
    }

    /// The configuration.
    pub fn spec(&self) -> Spec {
        self.spec
    }

    /// Builds (or reuses) the perturbation's state for frames of geometry `g`.
    pub fn prepare(&mut self, g: ImageGeometry) -> Result<&dyn CameraPerturbation> {
        let stale = !matches!(&self.built, Some((have, _)) if *have == g);
        if stale {
            let Builder::Camera(build) = self.spec.entry.build else {
                unreachable!("checked in from_spec")
            };
            let p = build(&CameraSetup {
                severity: self.spec.severity,
                seed: self.spec.seed,
                geometry: g,
            })?;
            self.built = Some((g, p));
        }
        Ok(self
            .built
            .as_ref()
            .map(|(_, p)| p.as_ref())
            .expect("built above"))
    }

    /// Perturbs `input` into `output` (same width, height and format; any strides).
    pub fn apply(
        &mut self,
        input: &ImageView<'_>,
        output: &mut ImageViewMut<'_>,
        seq: u64,
    ) -> Result<()> {
        if input.geometry() != output.geometry() {
            return Err(Error::GeometryMismatch {
                expected: input.geometry().to_string(),
                found: format!("output {}", output.geometry()),
            });
        }
        if input.width == 0 || input.height == 0 {
            return Ok(());
        }
        let p = self.prepare(input.geometry())?;
        p.apply(input, output, seq);
        Ok(())
    }

    /// Perturbs `input` into a new tightly packed image.
    pub fn apply_owned(&mut self, input: &ImageView<'_>, seq: u64) -> Result<Image> {
        let mut out = Image::with_geometry(input.geometry());
        self.apply(input, &mut out.view_mut(), seq)?;
        Ok(out)
    }

    /// Perturbs a frame in any encoding of [`crate::encoding::ENCODINGS`] into `out` (at least
    /// [`EncodedView::len`] bytes), in the frame's own encoding, size, step and byte order: the
    /// perturbation runs on the frame's 8-bit working view and the result is written back (see
    /// [`crate::encoding`]); bytes that are not pixels (row padding) are copied from `input`.
    /// `scratch` holds the conversion buffers, reused from frame to frame. For the working
    /// layouts this is [`CameraPerturber::apply`] straight into `out`.
    pub fn apply_encoded(
        &mut self,
        input: &EncodedView<'_>,
        out: &mut [u8],
        seq: u64,
        scratch: &mut Scratch,
    ) -> Result<()> {
        scratch.perturb(input, out, |i, o| self.apply(i, o, seq))
    }

    /// [`CameraPerturber::apply_encoded`] into a new buffer as long as the input's data.
    pub fn apply_encoded_owned(&mut self, input: &EncodedView<'_>, seq: u64) -> Result<Vec<u8>> {
        let mut out = vec![0; input.data().len()];
        self.apply_encoded(input, &mut out, seq, &mut Scratch::new())?;
        Ok(out)
    }
}

/// A LiDAR perturbation configured by ID, severity, seed and sensor model.
///
/// Object-level perturbations (L-D, L-E, L-F2, L-F3) act on the points inside object boxes. The
/// caller may supply the boxes per cloud; when it does not, the perturber runs its clustering
/// [`Detector`] (built once, with [`DetectorConfig::objects`] unless
/// [`LidarPerturber::set_detector`] says otherwise) on the **unperturbed** cloud.
pub struct LidarPerturber {
    spec: Spec,
    sensor: SensorModel,
    perturbation: Box<dyn LidarPerturbation>,
    points: Points,
    plan: Plan,
    detector: Option<Detector>,
    /// Boxes of the current cloud in the canonical frame, and in the sensor frame.
    boxes: Vec<Box3>,
    sensor_boxes: Vec<Box3>,
}

impl std::fmt::Debug for LidarPerturber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LidarPerturber")
            .field("spec", &self.spec)
            .field("sensor", &self.sensor.name)
            .finish()
    }
}

impl LidarPerturber {
    /// Validates the ID (must be a LiDAR perturbation) and severity, and builds its state.
    pub fn new(id: &str, severity: u8, seed: u64, sensor: SensorModel) -> Result<Self> {
        Self::from_spec(Spec::new(id, severity, seed)?, sensor)
    }

    /// Like [`LidarPerturber::new`] from a [`Spec`].
    pub fn from_spec(spec: Spec, sensor: SensorModel) -> Result<Self> {
        let perturbation = match spec.entry.build {
            Builder::Lidar(build) => build(&LidarSetup {
                severity: spec.severity,
                seed: spec.seed,
                sensor: sensor.clone(),
            })?,
            Builder::Camera(_) => return Err(wrong_modality(spec.entry, "point cloud")),
        };
        let detector = perturbation
            .needs()
            .boxes
            .then(|| Detector::new(DetectorConfig::default()));
        Ok(LidarPerturber {
            spec,
            sensor,
            perturbation,
            points: Points::default(),
            plan: Plan::default(),
            detector,
            boxes: Vec::new(),
            sensor_boxes: Vec::new(),
        })
    }

    /// Replaces the detector that supplies boxes when the caller gives none (object-level
    /// perturbations only; the others never run it).
    pub fn set_detector(&mut self, config: DetectorConfig) {
        if self.perturbation.needs().boxes {
            self.detector = Some(Detector::new(config));
        }
    }

    /// The boxes the last cloud was perturbed with, in the sensor's frame: the caller's, or the
    /// detector's on the unperturbed cloud (empty for perturbations that do not use boxes).
    pub fn last_boxes(&self) -> &[Box3] {
        &self.sensor_boxes
    }

    /// The configuration.
    pub fn spec(&self) -> Spec {
        self.spec
    }

    /// The sensor model.
    pub fn sensor(&self) -> &SensorModel {
        &self.sensor
    }

    /// An upper bound of the output size in bytes for `input` (what a caller loans).
    pub fn max_output_bytes(&self, input: &CloudView<'_>) -> usize {
        self.perturbation.max_output_points(input.len()) * input.layout().point_step as usize
    }

    /// Perturbs `input` into `out` in the input's layout and returns the output's shape. `boxes`
    /// are object boxes for the object-level perturbations; `None` lets the built-in detector find
    /// them on `input` (before it is perturbed).
    pub fn apply(
        &mut self,
        input: &CloudView<'_>,
        out: &mut [u8],
        seq: u64,
        boxes: Option<&[Box3]>,
    ) -> Result<CloudShape> {
        self.plan_frame(input, seq, boxes)?;
        self.plan.write(input, out)
    }

    /// The first half of [`LidarPerturber::apply`], for callers that allocate the output
    /// themselves: plans the perturbation of `input` and returns the exact size of the output in
    /// bytes. [`LidarPerturber::write_planned`] then writes it; together they give the same bytes
    /// as `apply`.
    pub fn plan(
        &mut self,
        input: &CloudView<'_>,
        seq: u64,
        boxes: Option<&[Box3]>,
    ) -> Result<usize> {
        self.plan_frame(input, seq, boxes)?;
        Ok(self.plan.output_bytes(input))
    }

    /// The second half of [`LidarPerturber::apply`]: writes the cloud planned by the last
    /// [`LidarPerturber::plan`] of the same `input` into `out` (at least as many bytes as `plan`
    /// returned) and returns its shape.
    pub fn write_planned(&self, input: &CloudView<'_>, out: &mut [u8]) -> Result<CloudShape> {
        self.plan.write(input, out)
    }

    /// Perturbs `input` into a new cloud.
    pub fn apply_owned(
        &mut self,
        input: &CloudView<'_>,
        seq: u64,
        boxes: Option<&[Box3]>,
    ) -> Result<Cloud> {
        self.plan_frame(input, seq, boxes)?;
        let mut data = vec![0u8; self.plan.output_bytes(input)];
        let shape = self.plan.write(input, &mut data)?;
        Cloud::from_vec(
            input.layout_arc().clone(),
            data,
            shape.width,
            shape.height,
            shape.row_step,
            input.is_dense,
        )
    }

    fn plan_frame(
        &mut self,
        input: &CloudView<'_>,
        seq: u64,
        boxes: Option<&[Box3]>,
    ) -> Result<()> {
        let needs = self.perturbation.needs();
        self.points.fill(input, &self.sensor, needs.ring)?;
        let axes = self.sensor.axes;
        self.boxes.clear();
        self.sensor_boxes.clear();
        if needs.boxes {
            match boxes {
                Some(b) => {
                    self.sensor_boxes.extend_from_slice(b);
                    self.boxes.extend(b.iter().map(|b| b.to_canonical(&axes)));
                }
                None => {
                    self.detector
                        .get_or_insert_with(|| Detector::new(DetectorConfig::default()))
                        .detect_into(&self.points, &mut self.boxes);
                    self.sensor_boxes
                        .extend(self.boxes.iter().map(|b| b.to_sensor(&axes)));
                }
            }
        }
        self.plan.clear();
        self.perturbation.plan(
            &self.points,
            &LidarFrame {
                seq,
                boxes: &self.boxes,
            },
            &mut self.plan,
        );
        self.plan.positions_to_sensor(&axes);
        Ok(())
    }
}

/// Either perturber, for code that handles both modalities by ID.
#[derive(Debug)]
pub enum Perturber {
    /// A camera perturbation.
    Camera(CameraPerturber),
    /// A LiDAR perturbation.
    Lidar(Box<LidarPerturber>),
}

impl Perturber {
    /// Configures the perturbation `id` (`sensor` is used by LiDAR perturbations only).
    pub fn new(id: &str, severity: u8, seed: u64, sensor: SensorModel) -> Result<Self> {
        let spec = Spec::new(id, severity, seed)?;
        Ok(match spec.entry.modality {
            Modality::Camera => Perturber::Camera(CameraPerturber::from_spec(spec)?),
            Modality::Lidar => Perturber::Lidar(Box::new(LidarPerturber::from_spec(spec, sensor)?)),
        })
    }
}
