//! Receiving frames: a subscriber and the listener of the stream's event service, for a WaitSet or
//! a plain blocking wait, and frames read in place.

use crate::error::{WireError, WireResult};
use crate::header::{FrameHeader, WireModality};
use crate::publisher::open_pubsub;
use crate::transport::{Ipc, StreamQos, Transport};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use perturb_core::cloud::{CloudView, PointLayout};
use perturb_core::image::ImageView;
use std::sync::Arc;
use std::time::Duration;

type PubSub = publish_subscribe::PortFactory<Ipc, [u8], FrameHeader>;

/// A publish-subscribe port and its event port.
type FramePorts = (Subscriber<Ipc, [u8], FrameHeader>, Listener<Ipc>);

/// Identifies the publisher a frame came from (a restarted publisher gets a new one).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Origin(u128);

impl Origin {
    /// The publisher's iceoryx2 id as a number (to store it, e.g. across a restart).
    pub fn raw(self) -> u128 {
        self.0
    }

    /// An origin from [`Origin::raw`].
    pub fn from_raw(raw: u128) -> Self {
        Origin(raw)
    }
}

/// A received frame: the shared-memory sample, read in place. Dropping it hands the memory back
/// to the publisher. Frames may be sent to another thread and read from several at once.
pub struct Frame {
    sample: Sample<Ipc, [u8], FrameHeader>,
}

// SAFETY: a `Frame` is only read through `&self` (`header`, `payload`, `origin`: reads through
// the sample's chunk pointers, which never change, into memory the publisher no longer writes
// once it has sent the sample, and of its plain details); the one mutation, handing the sample
// back, is in `Drop`, which owns it. iceoryx2's `Sample` is not `Sync` only because its chunk
// holds raw pointers (the compiler names nothing else: the thread-safe service's shared state is
// `Sync`). Reading one frame from several threads at once is what a ROS 1 egress does when it
// writes the frame's data to several subscribers' sockets.
#[allow(unsafe_code)]
unsafe impl Sync for Frame {}

impl std::fmt::Debug for Frame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Frame")
            .field("seq", &self.header().seq)
            .field("len", &self.payload().len())
            .finish()
    }
}

impl Frame {
    /// The header.
    pub fn header(&self) -> &FrameHeader {
        self.sample.user_header()
    }

    /// The whole payload (may be longer than the valid data, see [`Frame::data`]).
    pub fn payload(&self) -> &[u8] {
        self.sample.payload()
    }

    /// The valid bytes (`header.data_len`), after the version check.
    pub fn data(&self) -> WireResult<&[u8]> {
        self.header().valid_bytes(self.payload())
    }

    /// Which publisher sent it.
    pub fn origin(&self) -> Origin {
        Origin(self.sample.origin().value())
    }

    /// Checks header and payload agree (see [`FrameHeader::validate`]).
    pub fn validate(&self) -> WireResult<WireModality> {
        self.header().validate(self.payload().len())
    }

    /// The image, in place (validated).
    pub fn image(&self) -> WireResult<ImageView<'_>> {
        match self.validate()? {
            WireModality::Camera => self.header().image_view(self.payload()),
            WireModality::Lidar => Err(WireError::invalid("expected an image, got a point cloud")),
        }
    }

    /// The point cloud, in place (validated; parses the layout).
    pub fn cloud(&self) -> WireResult<CloudView<'_>> {
        self.cloud_cached(&mut LayoutCache::default())
    }

    /// The point cloud, in place, reusing the layout parsed for an earlier frame when it is the
    /// same.
    pub fn cloud_cached(&self, cache: &mut LayoutCache) -> WireResult<CloudView<'_>> {
        match self.validate()? {
            WireModality::Lidar => {
                let layout = cache.layout_for(self.header())?;
                self.header().cloud_view(self.payload(), layout)
            }
            WireModality::Camera => Err(WireError::invalid("expected a point cloud, got an image")),
        }
    }
}

/// The last parsed point layout, so a stream of clouds with one layout parses it once.
#[derive(Debug, Default)]
pub struct LayoutCache {
    last: Option<(FrameHeader, Arc<PointLayout>)>,
}

impl LayoutCache {
    /// The layout `header` describes.
    pub fn layout_for(&mut self, header: &FrameHeader) -> WireResult<Arc<PointLayout>> {
        if let Some((h, l)) = &self.last
            && h.same_layout(header)
        {
            return Ok(l.clone());
        }
        let l = Arc::new(header.point_layout()?);
        self.last = Some((*header, l.clone()));
        Ok(l)
    }
}

/// A subscriber of camera or LiDAR frames on one service, with the listener that wakes it.
///
/// Attach [`FrameSubscriber::listener`] to a WaitSet (or call [`FrameSubscriber::wait`]); on a
/// wake-up call [`FrameSubscriber::drain_notifications`] first, then [`FrameSubscriber::receive`]
/// until it returns `None`, so no frame waits for the next notification.
pub struct FrameSubscriber {
    service: String,
    buffer: usize,
    pubsub: PubSub,
    event: event::PortFactory<Ipc>,
    /// The ports; `None` only inside [`FrameSubscriber::reopen`], between dropping the old
    /// ones and creating the new ones.
    ports: Option<FramePorts>,
    reconnects: u64,
}

impl std::fmt::Debug for FrameSubscriber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameSubscriber")
            .field("service", &self.service)
            .field("buffer", &self.buffer)
            .finish()
    }
}

impl Transport {
    /// Opens (or creates) `service` and a subscriber on it with a queue of `buffer` samples
    /// (at most `qos.subscriber_buffer`; `None` for that maximum).
    pub fn subscriber(
        &self,
        service: &str,
        qos: &StreamQos,
        buffer: Option<usize>,
    ) -> WireResult<FrameSubscriber> {
        FrameSubscriber::open(self.node(), service, qos, buffer)
    }
}

impl FrameSubscriber {
    pub(crate) fn open(
        node: &Node<Ipc>,
        service: &str,
        qos: &StreamQos,
        buffer: Option<usize>,
    ) -> WireResult<Self> {
        let buffer = buffer
            .unwrap_or(qos.subscriber_buffer)
            .clamp(1, qos.subscriber_buffer);
        let (pubsub, event) = open_pubsub(node, service, qos)?;
        let ports = Self::ports(&pubsub, &event, service, buffer)?;
        Ok(FrameSubscriber {
            service: service.to_string(),
            buffer,
            pubsub,
            event,
            ports: Some(ports),
            reconnects: 0,
        })
    }

    fn ports(
        pubsub: &PubSub,
        event: &event::PortFactory<Ipc>,
        service: &str,
        buffer: usize,
    ) -> WireResult<FramePorts> {
        let subscriber = pubsub
            .subscriber_builder()
            .buffer_size(buffer)
            .create()
            .map_err(|e| WireError::iox(format!("creating a subscriber on `{service}`"), e))?;
        let listener = event
            .listener_builder()
            .create()
            .map_err(|e| WireError::iox(format!("creating a listener on `{service}`"), e))?;
        Ok((subscriber, listener))
    }

    /// Replaces the iceoryx2 ports with new ones (after a transport failure).
    pub fn reopen(&mut self) -> WireResult<()> {
        // Drop the old ports first so the service has room for the new ones (creating them
        // first failed with ExceedsMaxSupportedSubscribers on a service sized to the ports in
        // use). Until new ones exist, `receive` and `wait` return an error asking to reopen.
        self.ports = None;
        self.ports = Some(Self::ports(
            &self.pubsub,
            &self.event,
            &self.service,
            self.buffer,
        )?);
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

    /// Publishers currently connected to the service.
    pub fn publisher_count(&self) -> usize {
        self.pubsub.dynamic_config().number_of_publishers()
    }

    fn ports_or_err(&self) -> WireResult<&FramePorts> {
        self.ports.as_ref().ok_or_else(|| {
            WireError::iox(
                format!("`{}`", self.service),
                "the ports could not be created again: call reopen",
            )
        })
    }

    /// False after a [`FrameSubscriber::reopen`] that failed (until one succeeds).
    pub fn has_ports(&self) -> bool {
        self.ports.is_some()
    }

    /// The listener to attach to a WaitSet.
    ///
    /// # Panics
    /// After a failed [`FrameSubscriber::reopen`] (see [`FrameSubscriber::has_ports`]; the
    /// subscriber has no ports until a reopen succeeds).
    pub fn listener(&self) -> &Listener<Ipc> {
        &self
            .ports
            .as_ref()
            .expect("the ports exist (a failed reopen must be retried)")
            .1
    }

    /// Consumes pending wake-ups (call before draining frames with [`FrameSubscriber::receive`]).
    pub fn drain_notifications(&self) {
        if let Some((_, l)) = &self.ports {
            let _ = l.try_wait(|_| {});
        }
    }

    /// The next frame, if one is queued. On a transport failure (other than holding too many
    /// frames, see [`WireError::is_borrow_limit`]) call [`FrameSubscriber::reopen`].
    pub fn receive(&self) -> WireResult<Option<Frame>> {
        self.ports_or_err()?
            .0
            .receive()
            .map(|s| s.map(|sample| Frame { sample }))
            .map_err(|e| {
                if matches!(e, iceoryx2::port::ReceiveError::ExceedsMaxBorrows) {
                    WireError::BorrowLimit {
                        service: self.service.clone(),
                    }
                } else {
                    WireError::iox(format!("receiving on `{}`", self.service), e)
                }
            })
    }

    /// Waits up to `timeout` for a frame (blocking on the event listener, no polling); under a
    /// microsecond it only looks.
    pub fn wait(&self, timeout: Duration) -> WireResult<Option<Frame>> {
        if let Some(f) = self.receive()? {
            return Ok(Some(f));
        }
        // The listener's socket takes its timeout in microseconds, and 0 there means no timeout
        // at all: a zero wait would block until the next event, however long.
        if timeout < Duration::from_micros(1) {
            return Ok(None);
        }
        match self.ports_or_err()?.1.timed_wait(|_| {}, timeout) {
            // A signal cut the wait short (SIGCONT after SIGSTOP, a profiler's SIGPROF): not a
            // transport failure, just look for frames.
            Ok(_) | Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => {}
            Err(e) => return Err(WireError::iox(format!("waiting on `{}`", self.service), e)),
        }
        self.drain_notifications();
        self.receive()
    }
}

#[cfg(test)]
mod send_checks {
    fn assert_send<T: Send>() {}
    #[test]
    fn frames_and_ports_move_between_threads() {
        assert_send::<super::Frame>();
        assert_send::<super::FrameSubscriber>();
        assert_send::<crate::FramePublisher>();
        assert_send::<crate::Transport>();
    }
}
