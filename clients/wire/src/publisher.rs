//! Publishing frames: loan a shared-memory sample, fill it in place, send it and wake the
//! subscribers through the event service of the same name.

use crate::error::{WireError, WireResult};
use crate::header::{FrameHeader, image_bytes};
use crate::transport::{Ipc, StreamQos, Transport, monotonic_ns, open_error, service_name};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use perturb_core::cloud::CloudView;
use perturb_core::image::{ImageView, ImageViewMut};
use std::mem::MaybeUninit;
use std::time::{Duration, Instant};

/// Which hop timestamp [`FramePublisher::send`] writes into the header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hop {
    /// An ingress (bridge, replay, test publisher): `t_ingress_ns`.
    Ingress,
    /// The daemon's output: `t_daemon_tx_ns`.
    Daemon,
    /// Leave the header's timestamps alone.
    Keep,
}

type PubSub = publish_subscribe::PortFactory<Ipc, [u8], FrameHeader>;

/// Opens (or creates) the pub-sub service `service` with the stream's QoS.
pub(crate) fn open_pubsub(
    node: &Node<Ipc>,
    service: &str,
    qos: &StreamQos,
) -> WireResult<(PubSub, event::PortFactory<Ipc>)> {
    qos.validate()
        .map_err(|e| WireError::Config(format!("QoS of `{service}`: {e}")))?;
    let name = service_name(service)?;
    let pubsub = node
        .service_builder(&name)
        .publish_subscribe::<[u8]>()
        .user_header::<FrameHeader>()
        .max_publishers(qos.max_publishers)
        .max_subscribers(qos.max_subscribers)
        .subscriber_max_buffer_size(qos.subscriber_buffer)
        .subscriber_max_borrowed_samples(qos.subscriber_borrowed)
        .history_size(0)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| open_error(service, e))?;
    // The wake-up channel: one event service of the same name. Dead ports stay listed until
    // someone sweeps them, hence the slack.
    let event = node
        .service_builder(&name)
        .event()
        .max_notifiers(qos.max_publishers + 2)
        .max_listeners(qos.max_subscribers + 2)
        .open_or_create()
        .map_err(|e| open_error(service, e))?;
    Ok((pubsub, event))
}

/// A publish-subscribe port and its event port.
type FramePorts = (Publisher<Ipc, [u8], FrameHeader>, Notifier<Ipc>);

/// A publisher of camera or LiDAR frames on one service.
///
/// ```no_run
/// use perturb_wire::{FrameHeader, Hop, Stamp, StreamQos, Transport, TransportOptions};
/// use perturb_core::image::{Image, PixelFormat};
/// let t = Transport::open("camera_bridge", &TransportOptions::from_env()).unwrap();
/// let img = Image::new(800, 503, PixelFormat::Rgb8);
/// let mut publisher = t
///     .publisher("cam_front/raw", &StreamQos::default(), Hop::Ingress, img.data.len())
///     .unwrap();
/// let header = FrameHeader::for_image_view(0, Stamp::default(), "cam_front", &img.view()).unwrap();
/// publisher.publish_image(header, &img.view()).unwrap();
/// ```
pub struct FramePublisher {
    service: String,
    hop: Hop,
    initial_len: usize,
    qos: StreamQos,
    pubsub: PubSub,
    event: event::PortFactory<Ipc>,
    publisher: Publisher<Ipc, [u8], FrameHeader>,
    notifier: Notifier<Ipc>,
    reconnects: u64,
    /// Samples sent so far: the next one's [`FrameHeader::publish_index`].
    sent: u64,
}

impl std::fmt::Debug for FramePublisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FramePublisher")
            .field("service", &self.service)
            .field("hop", &self.hop)
            .finish()
    }
}

/// A loaned sample being filled. Send it with [`FramePublisher::send`]; dropping it returns the
/// memory unsent.
pub struct FrameLoan {
    sample: SampleMutUninit<Ipc, [MaybeUninit<u8>], FrameHeader>,
}

impl std::fmt::Debug for FrameLoan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameLoan")
            .field("len", &self.len())
            .finish()
    }
}

impl FrameLoan {
    /// The header.
    pub fn header(&self) -> &FrameHeader {
        self.sample.user_header()
    }

    /// The header, to fill in.
    pub fn header_mut(&mut self) -> &mut FrameHeader {
        self.sample.user_header_mut()
    }

    /// Payload length in bytes.
    pub fn len(&self) -> usize {
        self.sample.payload().len()
    }

    /// True for an empty payload.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The payload as bytes, to be written in place.
    ///
    /// The bytes hold whatever the memory held before (a previous frame, or zeros); write every
    /// byte you declare valid in [`FrameHeader::data_len`].
    // iceoryx2's loans are uninitialised shared memory.
    #[allow(unsafe_code)]
    pub fn payload_mut(&mut self) -> &mut [u8] {
        let p = self.sample.payload_mut();
        // SAFETY: the payload lies in a shared-memory mapping (an mmap of a POSIX shm object):
        // the kernel zero-fills its pages on creation and afterwards they are only ever written
        // with byte values, so every byte is initialised memory; `MaybeUninit<u8>` and `u8`
        // have the same layout. Handing it out as `&mut [u8]` lets producers write in place in
        // one pass instead of clearing the loan first.
        unsafe { std::slice::from_raw_parts_mut(p.as_mut_ptr().cast::<u8>(), p.len()) }
    }

    /// A writable image view of the payload with the header's geometry (set the header first).
    pub fn image_mut(&mut self) -> WireResult<ImageViewMut<'_>> {
        let h = *self.header();
        h.image_view_mut(self.payload_mut())
    }
}

impl Transport {
    /// Opens (or creates) `service` and a publisher on it that stamps `hop` when sending.
    /// `initial_len` sizes the first shared-memory segment (the expected frame size); larger
    /// frames make iceoryx2 grow the segment (power-of-two strategy).
    pub fn publisher(
        &self,
        service: &str,
        qos: &StreamQos,
        hop: Hop,
        initial_len: usize,
    ) -> WireResult<FramePublisher> {
        FramePublisher::open(self.node(), service, qos, hop, initial_len)
    }
}

impl FramePublisher {
    pub(crate) fn open(
        node: &Node<Ipc>,
        service: &str,
        qos: &StreamQos,
        hop: Hop,
        initial_len: usize,
    ) -> WireResult<Self> {
        let (pubsub, event) = open_pubsub(node, service, qos)?;
        let (publisher, notifier) = Self::ports(&pubsub, &event, service, qos, initial_len)?;
        Ok(FramePublisher {
            service: service.to_string(),
            hop,
            initial_len,
            qos: *qos,
            pubsub,
            event,
            publisher,
            notifier,
            reconnects: 0,
            sent: 0,
        })
    }

    fn ports(
        pubsub: &PubSub,
        event: &event::PortFactory<Ipc>,
        service: &str,
        qos: &StreamQos,
        initial_len: usize,
    ) -> WireResult<FramePorts> {
        let publisher = pubsub
            .publisher_builder()
            .initial_max_slice_len(initial_len.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .max_loaned_samples(qos.publisher_loans)
            .create()
            .map_err(|e| WireError::iox(format!("creating a publisher on `{service}`"), e))?;
        let notifier = event
            .notifier_builder()
            .create()
            .map_err(|e| WireError::iox(format!("creating a notifier on `{service}`"), e))?;
        Ok((publisher, notifier))
    }

    /// Replaces this publisher's iceoryx2 ports with new ones (after a transport failure).
    pub fn reopen(&mut self) -> WireResult<()> {
        let (p, n) = Self::ports(
            &self.pubsub,
            &self.event,
            &self.service,
            &self.qos,
            self.initial_len,
        )?;
        self.publisher = p;
        self.notifier = n;
        self.reconnects += 1;
        Ok(())
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// How often the ports were recreated after a failure.
    pub fn reconnects(&self) -> u64 {
        self.reconnects
    }

    /// Subscribers currently connected to the service.
    pub fn subscriber_count(&self) -> usize {
        self.pubsub.dynamic_config().number_of_subscribers()
    }

    /// Waits (sleeping in 5 ms steps) until at least `n` subscribers are connected; false on
    /// timeout. For start-up ordering in tests and tools, not for the data path.
    pub fn wait_for_subscribers(&self, n: usize, timeout: Duration) -> bool {
        let start = Instant::now();
        while self.subscriber_count() < n {
            if start.elapsed() > timeout {
                return false;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        true
    }

    /// Loans a sample with a payload of `len` bytes, its header set to the default (this wire
    /// version, nothing else).
    pub fn loan(&self, len: usize) -> WireResult<FrameLoan> {
        let sample = self
            .publisher
            .loan_slice_uninit(len)
            .map_err(|e| WireError::iox(format!("loaning {len} bytes on `{}`", self.service), e))?;
        Ok(FrameLoan { sample })
    }

    /// Sends a filled loan, stamping this publisher's hop timestamp, and wakes the subscribers.
    /// Returns the number of subscribers reached. A transport failure recreates the ports once
    /// (the frame itself is lost and the error returned).
    // iceoryx2's loans are uninitialised shared memory.
    #[allow(unsafe_code)]
    pub fn send(&mut self, loan: FrameLoan) -> WireResult<usize> {
        // SAFETY: see `FrameLoan::payload_mut`: the shared memory is always initialised bytes.
        let mut sample = unsafe { loan.sample.assume_init() };
        let now = monotonic_ns();
        sample.user_header_mut().publish_index = self.sent;
        match self.hop {
            Hop::Ingress => sample.user_header_mut().t_ingress_ns = now,
            Hop::Daemon => sample.user_header_mut().t_daemon_tx_ns = now,
            Hop::Keep => {}
        }
        match sample.send() {
            Ok(n) => {
                self.sent += 1;
                // A failed wake-up only delays the frame until the next notification or the
                // subscriber's timeout; it is not worth failing the send for.
                let _ = self.notifier.notify();
                Ok(n)
            }
            Err(e) => {
                let err = WireError::iox(format!("sending on `{}`", self.service), e);
                self.reopen()?;
                Err(err)
            }
        }
    }

    /// Publishes an image: loans `header.data_len` bytes, copies the rows with the header's
    /// step (padding zeroed), sends. The header must describe `image` (see
    /// [`FrameHeader::for_image_view`]).
    pub fn publish_image(
        &mut self,
        header: FrameHeader,
        image: &ImageView<'_>,
    ) -> WireResult<usize> {
        let step = header.step as usize;
        let row = image.geometry().row_bytes();
        if header.width != image.width
            || header.height != image.height
            || step < row
            || header.pixel_format()? != image.format
        {
            return Err(WireError::invalid(format!(
                "header ({}x{} {} step {}) does not describe the image ({})",
                header.width,
                header.height,
                header.encoding().unwrap_or("?"),
                header.step,
                image.geometry()
            )));
        }
        let len = image_bytes(image.height, step, row);
        let mut loan = self.loan(len)?;
        *loan.header_mut() = header;
        loan.header_mut().data_len = len as u64;
        let out = loan.payload_mut();
        if step == image.stride && step == row {
            out.copy_from_slice(&image.data()[..len]);
        } else {
            for y in 0..image.height as usize {
                let dst = &mut out[y * step..];
                let n = row.min(dst.len());
                dst[..n].copy_from_slice(image.row(y));
                let pad_end = (step).min(dst.len());
                dst[n..pad_end].fill(0);
            }
        }
        self.send(loan)
    }

    /// Publishes a point cloud: loans the cloud's bytes, copies them, sends. The header must
    /// describe `cloud` (see [`FrameHeader::for_cloud_view`]).
    pub fn publish_cloud(
        &mut self,
        header: FrameHeader,
        cloud: &CloudView<'_>,
    ) -> WireResult<usize> {
        let data = cloud.data();
        let len = crate::header::cloud_bytes(
            cloud.height,
            cloud.row_step,
            cloud.width,
            cloud.layout().point_step,
        );
        let Some(src) = data.get(..len) else {
            return Err(WireError::invalid(format!(
                "cloud holds {} bytes, its shape needs {len}",
                data.len()
            )));
        };
        let mut loan = self.loan(len)?;
        *loan.header_mut() = header;
        loan.header_mut().data_len = len as u64;
        loan.payload_mut().copy_from_slice(src);
        self.send(loan)
    }

    /// Publishes raw bytes under an arbitrary header, unchecked (for tools and for tests that
    /// need malformed frames).
    pub fn publish_raw(&mut self, header: FrameHeader, payload: &[u8]) -> WireResult<usize> {
        let mut loan = self.loan(payload.len())?;
        *loan.header_mut() = header;
        loan.payload_mut().copy_from_slice(payload);
        self.send(loan)
    }
}
