//! `camera_info` travels with its image: a driver's image and camera_info topics (moved aside
//! under /unperturbed/...) read by the bridge's ingress, and both published under the names the
//! stack subscribes to, each camera_info unchanged (same header, same calibration) and with the
//! stamp of an image that went out. ROS 1 against rospy publishers and subscribers, ROS 2 against
//! the independent Cyclone DDS peer.

use perturb_tests::{
    Namespace, Ros1Master, collect_lines, dds_peer, have_python_modules, have_ros1, kill_all,
    ros1_lines, ros1_peer, ros1_ready, start_bridge, stdout_of,
};
use serde_json::Value;
use std::time::Duration;

fn interrupt(c: &mut std::process::Child) -> bool {
    perturb_wire::process::interrupt(c, Duration::from_secs(15)).is_some_and(|s| s.success())
}

/// Every camera_info sent arrived once, unchanged; each has the stamp of an image received.
fn check(sent: &[Value], got: &[Value], images: &[Value], nsec: &str, fields: &[&str]) {
    assert_eq!(
        got.len(),
        sent.len(),
        "camera_info messages lost: got {got:?}"
    );
    for s in sent {
        let g = got
            .iter()
            .find(|g| g["sec"] == s["sec"] && g[nsec] == s[nsec])
            .unwrap_or_else(|| panic!("camera_info {s} did not arrive"));
        for f in fields {
            assert_eq!(g[*f], s[*f], "`{f}` changed: {g} vs {s}");
        }
        assert!(
            images
                .iter()
                .any(|i| i["sec"] == s["sec"] && i[nsec] == s[nsec]),
            "no image with the stamp of {s}"
        );
    }
}

#[test]
fn ros1_camera_info_is_relayed_with_its_images() {
    if !have_ros1() {
        return;
    }
    let ns = Namespace::new("caminfo-ros1");
    let master = Ros1Master::start(&ns.dir);
    let cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &cfg,
        "[bridge]\nname = \"caminfo\"\nbus = \"local\"\n\n[ros1]\nhostname = \"127.0.0.1\"\n\n\
         [[ingress]]\ntopic = \"/unperturbed/cam/image_raw\"\ntype = \"image\"\nstream = \"cam\"\ntransport = \"ros1\"\n\
         camera_info = \"/unperturbed/cam/camera_info\"\n\n\
         [[egress]]\nstream = \"cam\"\ntopic = \"/cam/image_raw\"\ntransport = \"ros1\"\ncamera_info = \"/cam/camera_info\"\n",
    )
    .unwrap();
    let mut bridge = start_bridge(&ns, Some(&master), &cfg, "bridge.log");
    let sub = |topic: &str, ty: &str, name: &str| {
        let mut c = ros1_peer(
            &master,
            &[
                "sub",
                "--topic",
                topic,
                "--type",
                ty,
                "--count",
                "100000",
                "--timeout",
                "60",
                "--name",
                name,
            ],
        );
        let lines = collect_lines(ros1_ready(&mut c));
        (c, lines)
    };
    let (si, li) = sub("/cam/image_raw", "image", "img");
    let (sc, lc) = sub("/cam/camera_info", "camera_info", "info");
    std::thread::sleep(Duration::from_secs(2));
    let publish = |ty: &str, topic: &str, name: &str| {
        ros1_peer(
            &master,
            &[
                "pub",
                "--topic",
                topic,
                "--type",
                ty,
                "--count",
                "20",
                "--rate",
                "10",
                "--size",
                "64x48",
                "--frame-id",
                "cam_optical",
                "--name",
                name,
                "--stamp-base",
                "1000",
            ],
        )
    };
    let mut pi = publish("image", "/unperturbed/cam/image_raw", "img");
    let mut pc = publish("camera_info", "/unperturbed/cam/camera_info", "info");
    let sent_images = ros1_lines(stdout_of(&mut pi), &mut pi);
    let sent_info = ros1_lines(stdout_of(&mut pc), &mut pc);
    std::thread::sleep(Duration::from_secs(1));
    assert!(interrupt(&mut bridge));
    let mut peers = vec![si, sc];
    kill_all(&mut peers);
    let (images, infos) = (li.join().unwrap(), lc.join().unwrap());
    assert_eq!(images.len(), sent_images.len());
    check(
        &sent_info,
        &infos,
        &images,
        "nsec",
        &[
            "frame_id",
            "width",
            "height",
            "distortion_model",
            "D",
            "K",
            "seq",
        ],
    );
}

#[test]
fn ros2_camera_info_is_relayed_with_its_images() {
    if !have_python_modules("python3", &["cyclonedds"], "pip install cyclonedds") {
        return;
    }
    let ns = Namespace::new("caminfo-ros2");
    let domain = (std::process::id() % 50) as u16 * 4 + 23;
    let dom = domain.to_string();
    let cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            "[bridge]\nname = \"caminfo\"\nbus = \"local\"\n\n[dds]\ndomain_id = {domain}\ninterfaces = [\"lo\"]\n\n\
             [[ingress]]\ntopic = \"/unperturbed/cam/image_raw\"\ntype = \"image\"\nstream = \"cam\"\n\
             camera_info = \"/unperturbed/cam/camera_info\"\n\n\
             [[egress]]\nstream = \"cam\"\ntopic = \"/cam/image_raw\"\ncamera_info = \"/cam/camera_info\"\n"
        ),
    )
    .unwrap();
    let mut bridge = start_bridge(&ns, None, &cfg, "bridge.log");
    let listen = |topic: &str, ty: &str| {
        let mut c = dds_peer(&[
            "listen",
            "--topic",
            topic,
            "--type",
            ty,
            "--count",
            "100000",
            "--timeout",
            "60",
            "--domain",
            &dom,
        ]);
        let lines = collect_lines(stdout_of(&mut c));
        (c, lines)
    };
    let (si, li) = listen("/cam/image_raw", "image");
    let (sc, lc) = listen("/cam/camera_info", "camera_info");
    std::thread::sleep(Duration::from_secs(3));
    let publish = |ty: &str, topic: &str| {
        let mut c = dds_peer(&[
            "publish", "--topic", topic, "--type", ty, "--count", "15", "--rate", "10", "--domain",
            &dom,
        ]);
        let lines = collect_lines(stdout_of(&mut c));
        (c, lines)
    };
    let (mut pi, pil) = publish("image", "/unperturbed/cam/image_raw");
    let (mut pc, pcl) = publish("camera_info", "/unperturbed/cam/camera_info");
    let _ = (pi.wait(), pc.wait());
    let (sent_images, sent_info) = (pil.join().unwrap(), pcl.join().unwrap());
    std::thread::sleep(Duration::from_secs(1));
    assert!(interrupt(&mut bridge));
    let mut peers = vec![si, sc];
    kill_all(&mut peers);
    let (images, infos) = (li.join().unwrap(), lc.join().unwrap());
    assert_eq!(images.len(), sent_images.len(), "images lost");
    check(
        &sent_info,
        &infos,
        &images,
        "nanosec",
        &["frame_id", "width", "height", "distortion_model", "d", "k"],
    );
}
