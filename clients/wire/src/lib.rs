//! # perturb-wire
//!
//! The shared-memory wire format of the perturbation middleware and the small typed
//! publish/subscribe API every process uses (the bridges, the daemon `perturbd`, the `perturb`
//! tool, the tests and users' own programs), over [iceoryx2](https://docs.rs/iceoryx2) 0.10.
//!
//! - A frame is an iceoryx2 sample: a `[u8]` payload holding the image rows or the PointCloud2
//!   point data exactly as in the ROS message, plus a [`FrameHeader`] (`#[repr(C)]`, versioned)
//!   with the sequence number, ROS stamp and frame_id, image geometry or point layout, one
//!   monotonic timestamp per hop and the perturbation applied.
//! - [`Transport`] joins an iceoryx2 namespace ([`TransportOptions`]: prefix, root, config file;
//!   tests isolate themselves with [`TransportOptions::isolated`]) and sweeps stale resources of
//!   dead processes.
//! - [`FramePublisher`] loans a sample, lets the caller fill it in place (as an
//!   [`ImageViewMut`](perturb_core::image::ImageViewMut) or `&mut [u8]`), sends it and notifies
//!   the event service of the same name; [`FrameSubscriber`] wakes on that event (WaitSet or
//!   blocking wait, no polling) and hands out [`Frame`]s read in place as
//!   [`ImageView`](perturb_core::image::ImageView) / [`CloudView`](perturb_core::cloud::CloudView).
//! - Service names: `<stream>/raw` into the daemon, `<stream>/perturbed` out of it ([`names`]).
//! - [`control`]: the daemon's request-response control channel (`perturb ctl`).
//!
//! ```no_run
//! use perturb_wire::{FrameHeader, Hop, Stamp, StreamQos, Transport, TransportOptions, names};
//! use perturb_core::image::{Image, PixelFormat};
//! use std::time::Duration;
//! let t = Transport::open("example", &TransportOptions::from_env()).unwrap();
//! let qos = StreamQos::default();
//! let sub = t.subscriber(&names::perturbed("cam_front"), &qos, None).unwrap();
//! let mut publisher = t.publisher(&names::raw("cam_front"), &qos, Hop::Ingress, 1 << 20).unwrap();
//! let img = Image::new(640, 480, PixelFormat::Rgb8);
//! let h = FrameHeader::for_image_view(0, Stamp::default(), "cam_front", &img.view()).unwrap();
//! publisher.publish_image(h, &img.view()).unwrap();
//! if let Some(frame) = sub.wait(Duration::from_secs(1)).unwrap() {
//!     let view = frame.image().unwrap(); // in shared memory, no copy
//!     println!("seq {} {}x{} applied {:?}", frame.header().seq, view.width, view.height,
//!              frame.header().applied());
//! }
//! ```

pub mod control;
mod error;
pub mod header;
pub mod process;
mod publisher;
mod subscriber;
mod transport;

pub use error::{WireError, WireResult};
pub use header::{Applied, FrameHeader, MAX_FIELDS, Stamp, WIRE_VERSION, WireField, WireModality};
pub use publisher::{FrameLoan, FramePublisher, Hop};
pub use subscriber::{Frame, FrameSubscriber, LayoutCache, Origin};
pub use transport::{
    ENV_CONFIG, ENV_PREFIX, ENV_ROOT, Ipc, StreamQos, SweepReport, Transport, TransportOptions,
    monotonic_ns, names, sweep_dead_nodes,
};

/// The iceoryx2 crate this wire format is built on, for programs that attach the listeners to
/// their own WaitSet.
pub use iceoryx2;
