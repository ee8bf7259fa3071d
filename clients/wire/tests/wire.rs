//! Publish and receive through real iceoryx2 shared memory (two nodes of one process, in a
//! namespace private to each test).

use perturb_core::image::{Image, PixelFormat};
use perturb_core::synthetic;
use perturb_wire::control::{ControlClient, ControlRequest, ControlResponse, ControlServer};
use perturb_wire::{
    FrameHeader, Hop, Stamp, StreamQos, Transport, TransportOptions, WireError, WireModality,
    monotonic_ns,
};
use std::time::Duration;

/// Two transports in a namespace private to the test; the namespace's files are removed when
/// the guard goes (declared first, it is dropped after the transports).
struct Pair(Cleanup, Transport, Transport);
struct Cleanup(TransportOptions);
impl Drop for Cleanup {
    fn drop(&mut self) {
        let _ = self.0.remove_namespace_files();
    }
}

fn pair(tag: &str) -> Pair {
    let opts = TransportOptions::isolated(tag);
    let a = Transport::open("pub", &opts).unwrap();
    let b = Transport::open("sub", &opts).unwrap();
    Pair(Cleanup(opts), a, b)
}

#[test]
fn image_arrives_in_place_with_header_and_hop_stamp() {
    let Pair(_clean, a, b) = pair("image");
    let qos = StreamQos::default();
    let sub = b.subscriber("cam/raw", &qos, None).unwrap();
    let mut publisher = a.publisher("cam/raw", &qos, Hop::Ingress, 16).unwrap();
    assert!(publisher.wait_for_subscribers(1, Duration::from_secs(5)));
    let img = synthetic::street_image(64, 40, 3);
    let before = monotonic_ns();
    let h =
        FrameHeader::for_image_view(42, Stamp { sec: 7, nanosec: 9 }, "cam", &img.view()).unwrap();
    // Larger than the initial 16 bytes: the segment grows.
    assert_eq!(publisher.publish_image(h, &img.view()).unwrap(), 1);
    let frame = sub.wait(Duration::from_secs(5)).unwrap().expect("frame");
    let v = frame.image().unwrap();
    assert_eq!(v.data(), &img.data[..]);
    let hd = frame.header();
    assert_eq!((hd.seq, hd.stamp_sec, hd.stamp_nanosec), (42, 7, 9));
    assert_eq!(hd.frame_id().unwrap(), "cam");
    assert!(hd.t_ingress_ns >= before);
    assert_eq!(hd.applied(), None);
}

#[test]
fn a_wait_under_a_microsecond_only_looks() {
    let Pair(_clean, a, b) = pair("zerowait");
    let qos = StreamQos::default();
    let sub = b.subscriber("cam/raw", &qos, None).unwrap();
    let mut publisher = a.publisher("cam/raw", &qos, Hop::Ingress, 1 << 16).unwrap();
    assert!(publisher.wait_for_subscribers(1, Duration::from_secs(5)));
    // Nothing published: these used to block until the next frame (the socket's 0 = forever).
    assert!(sub.wait(Duration::ZERO).unwrap().is_none());
    assert!(sub.wait(Duration::from_nanos(500)).unwrap().is_none());
    let img = synthetic::street_image(64, 40, 3);
    let h = FrameHeader::for_image_view(1, Stamp { sec: 1, nanosec: 0 }, "cam", &img.view());
    publisher.publish_image(h.unwrap(), &img.view()).unwrap();
    let f = sub
        .wait(Duration::ZERO)
        .unwrap()
        .expect("the published frame");
    assert_eq!(f.header().seq, 1);
}

#[test]
fn cloud_with_padded_rows_and_wrong_version_is_refused() {
    let Pair(_clean, a, b) = pair("cloud");
    let qos = StreamQos::default();
    let sub = b.subscriber("lidar/raw", &qos, None).unwrap();
    let mut publisher = a.publisher("lidar/raw", &qos, Hop::Ingress, 1).unwrap();
    let cloud = synthetic::vlp32c_scan(0);
    let h = FrameHeader::for_cloud_view(1, Stamp::default(), "velodyne", &cloud.view()).unwrap();
    publisher.publish_cloud(h, &cloud.view()).unwrap();
    let f = sub.wait(Duration::from_secs(5)).unwrap().unwrap();
    assert_eq!(f.validate().unwrap(), WireModality::Lidar);
    let v = f.cloud().unwrap();
    assert_eq!(v.len(), cloud.len());
    assert_eq!(v.data(), &cloud.data[..]);
    drop(f);

    let mut bad = h;
    bad.version = 99;
    publisher.publish_raw(bad, &cloud.data).unwrap();
    let f = sub.wait(Duration::from_secs(5)).unwrap().unwrap();
    let e = f.cloud().unwrap_err();
    assert!(
        matches!(e, WireError::VersionMismatch { found: 99, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("version 99"), "{e}");
}

#[test]
fn header_disagreeing_with_payload_is_invalid() {
    let Pair(_clean, a, b) = pair("short");
    let qos = StreamQos::default();
    let sub = b.subscriber("cam/raw", &qos, None).unwrap();
    let mut publisher = a.publisher("cam/raw", &qos, Hop::Ingress, 1).unwrap();
    let img = Image::new(8, 8, PixelFormat::Rgb8);
    let h = FrameHeader::for_image_view(0, Stamp::default(), "c", &img.view()).unwrap();
    publisher.publish_raw(h, &img.data[..100]).unwrap();
    let f = sub.wait(Duration::from_secs(5)).unwrap().unwrap();
    let e = f.image().unwrap_err();
    assert!(e.is_invalid_frame(), "{e}");
}

#[test]
fn control_round_trip() {
    let Pair(_clean, a, b) = pair("control");
    let server = ControlServer::create(&a, "perturb/control").unwrap();
    let client = ControlClient::connect(&b, "perturb/control").unwrap();
    let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
    let t = std::thread::spawn(move || {
        let start = std::time::Instant::now();
        let mut seen = 0;
        while seen == 0 && start.elapsed() < Duration::from_secs(5) {
            let _ = server
                .listener()
                .timed_wait(|_| {}, Duration::from_millis(100));
            seen += server
                .serve(|r| match r {
                    ControlRequest::Off { stream } => ControlResponse::ack(format!("{stream} off")),
                    _ => ControlResponse::error("unexpected"),
                })
                .unwrap();
        }
        // The answer lives in the server's shared memory: keep the server until it was read.
        let _ = done_rx.recv_timeout(Duration::from_secs(10));
        seen
    });
    let r = client
        .request(
            &ControlRequest::Off {
                stream: "cam".into(),
            },
            Duration::from_secs(5),
        )
        .unwrap();
    done_tx.send(()).unwrap();
    assert!(r.ok);
    assert_eq!(r.message.as_deref(), Some("cam off"));
    assert_eq!(t.join().unwrap(), 1);
}

#[test]
fn control_client_without_daemon_says_so() {
    let Pair(_clean, _a, b) = pair("nodaemon");
    let e = ControlClient::connect(&b, "perturb/control")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no perturbd"), "{e}");
}

/// Reopening a subscriber on a service sized for exactly the subscribers in use works: the old
/// ports are dropped first. (It failed with ExceedsMaxSupportedSubscribers, which a recorder
/// resumed after SIGSTOP logged as a bad message.)
#[test]
fn a_subscriber_reopens_on_a_service_without_spare_room() {
    let Pair(_clean, a, b) = pair("reopen");
    let qos = StreamQos {
        max_subscribers: 1,
        ..StreamQos::default()
    };
    let mut sub = b.subscriber("cam/raw", &qos, None).unwrap();
    let mut publisher = a.publisher("cam/raw", &qos, Hop::Ingress, 16).unwrap();
    assert!(publisher.wait_for_subscribers(1, Duration::from_secs(5)));
    sub.reopen()
        .expect("reopen without a spare subscriber slot");
    assert!(sub.has_ports());
    assert_eq!(sub.reconnects(), 1);
    assert!(publisher.wait_for_subscribers(1, Duration::from_secs(5)));
    let img = synthetic::street_image(8, 4, 1);
    let h =
        FrameHeader::for_image_view(5, Stamp { sec: 1, nanosec: 0 }, "cam", &img.view()).unwrap();
    assert_eq!(publisher.publish_image(h, &img.view()).unwrap(), 1);
    let frame = sub.wait(Duration::from_secs(5)).unwrap().expect("frame");
    assert_eq!(frame.header().seq, 5);
}
