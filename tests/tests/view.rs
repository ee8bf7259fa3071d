//! The live view against an independent client: the Foxglove WebSocket protocol's own client
//! library from npm (`@foxglove/ws-protocol`, run by node: `tests/tests/view_client/client.js`),
//! connected on loopback to a bridge that carries a synthetic camera and LiDAR through perturbd:
//!
//! - it subscribes to every channel the bridge advertises; the camera frames decode (jpeg-js)
//!   as JPEGs of the stream's shrunk size, the clouds as `foxglove.PointCloud`s (protobufjs over
//!   the advertised descriptors), the statistics, status and events messages validate (ajv)
//!   against the JSON schemas advertised with them;
//! - its calls of the set / off / kill / arm services change what perturbd applies, as
//!   `perturb ctl status` shows, and a bad request is refused with the reason;
//! - a second client that connects and then stops reading (a hung viewer) costs the pipeline
//!   nothing: perturbd drops no frame and a subscriber of the perturbed stream gets every one;
//! - a camera_info relayed by a ROS 1 ingress (rospy publishers) reaches the viewer as a
//!   `foxglove.CameraCalibration` scaled with the JPEG (size and K).
//!
//! Needs node and the client's npm packages (`cd tests/tests/view_client && npm ci`, which
//! `.ci/run` does), and for the calibration Debian's ROS 1: skipped with a message when they are
//! missing, a failure under `CI=true` or `PERTURB_REQUIRE_ORACLES=1`.

use perturb_tests::{Namespace, exe, free_port, workspace};
use serde_json::{Value, json};
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

/// The client's folder, if node and its packages are there.
fn view_client() -> Option<PathBuf> {
    let dir = workspace().join("tests/tests/view_client");
    let node = Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let packages = dir.join("node_modules/@foxglove/ws-protocol").exists();
    if node && packages {
        return Some(dir);
    }
    let what = if node {
        format!(
            "the view client's npm packages are missing ({}: cd tests/tests/view_client && npm ci)",
            dir.join("node_modules").display()
        )
    } else {
        "node is missing (apt-get install nodejs npm, then cd tests/tests/view_client && npm ci)"
            .to_string()
    };
    let required = std::env::var("CI").as_deref() == Ok("true")
        || std::env::var("PERTURB_REQUIRE_ORACLES").as_deref() == Ok("1");
    assert!(
        !required,
        "{what}, and CI=true or PERTURB_REQUIRE_ORACLES=1"
    );
    eprintln!("SKIP: {what}");
    None
}

/// A running `client.js`: its commands in, its JSON lines out.
struct Client {
    child: Child,
    stdin: ChildStdin,
    lines: Receiver<Value>,
    name: &'static str,
}

impl Client {
    fn start(dir: &PathBuf, url: &str, name: &'static str, extra: &[&str]) -> Client {
        let mut child = Command::new("node")
            .arg(dir.join("client.js"))
            .arg(url)
            .args(extra)
            .current_dir(dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("starting node");
        let stdin = child.stdin.take().expect("piped stdin");
        let out = BufReader::new(child.stdout.take().expect("piped stdout"));
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for l in out.lines().map_while(Result::ok) {
                let v = serde_json::from_str(&l).unwrap_or_else(|_| json!({ "text": l }));
                if tx.send(v).is_err() {
                    break;
                }
            }
        });
        Client {
            child,
            stdin,
            lines,
            name,
        }
    }

    /// The next line that has `key`, within `timeout` (others are kept in the failure message).
    fn expect(&self, key: &str, timeout: Duration) -> Value {
        let end = Instant::now() + timeout;
        let mut seen = Vec::new();
        loop {
            let left = end.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(v) if v.get(key).is_some() => return v,
                Ok(v) => seen.push(v),
                Err(_) => panic!(
                    "client {}: no `{key}` line within {timeout:?}; it said {seen:?}",
                    self.name
                ),
            }
        }
    }

    fn send(&mut self, cmd: Value) {
        writeln!(self.stdin, "{cmd}").expect("writing to the client");
        self.stdin.flush().expect("writing to the client");
    }

    /// Calls a service and returns the client's line about it (`reply` or `error`).
    fn call(&mut self, service: &str, request: Value) -> Value {
        self.send(json!({ "cmd": "call", "service": service, "request": request }));
        let r = self.expect("service", Duration::from_secs(10));
        assert_eq!(r["service"], service, "{r}");
        r
    }

    fn report(&mut self) -> Value {
        self.send(json!({ "cmd": "report" }));
        self.expect("report", Duration::from_secs(10))["report"].clone()
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `perturb ctl status --json`'s entry for `stream`.
fn status(ns: &Namespace, stream: &str) -> Value {
    let o = ns.ctl(&["status", "--json"]);
    assert!(
        o.status.success(),
        "perturb ctl status: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v: Value = serde_json::from_slice(&o.stdout).expect("status JSON");
    v.as_array()
        .and_then(|a| a.iter().find(|s| s["name"] == stream))
        .unwrap_or_else(|| panic!("no stream {stream} in {v}"))
        .clone()
}

/// Waits until something accepts connections on `port` of 127.0.0.1.
fn wait_listening(port: u16, bridge: &mut Child, log: &std::path::Path) {
    let end = Instant::now() + Duration::from_secs(30);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if let Ok(Some(st)) = bridge.try_wait() {
            panic!(
                "the bridge exited ({st}):\n{}",
                std::fs::read_to_string(log).unwrap_or_default()
            );
        }
        assert!(
            Instant::now() < end,
            "the view did not listen on {port} within 30 s:\n{}",
            std::fs::read_to_string(log).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn an_independent_foxglove_client_sees_every_channel_and_drives_the_daemon_and_a_hung_one_costs_nothing()
 {
    let Some(client_dir) = view_client() else {
        return;
    };
    let ns = Namespace::new("view");
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\nqos = { subscriber_buffer = 8 }\n\n\
         [[streams]]\nname = \"lid\"\nmodality = \"lidar\"\nsensor = \"vlp32c\"\nqos = { subscriber_buffer = 8 }\n\
         perturbation = { id = \"L-B1\", severity = 2, seed = 5 }\n",
    )
    .unwrap();
    // Rates low enough that a CI machine running other tests does not starve perturbd's worker
    // for two frame periods (its queue holds two): a drop here is then the view's doing.
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let sink = ns.start_sink(&daemon_cfg, "cam", &ns.dir.join("sink"), &["--idle", "3"]);

    let port = free_port();
    let bridge_cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &bridge_cfg,
        format!(
            "[bridge]\nname = \"viewtest\"\nqos = {{ subscriber_buffer = 8 }}\n\n\
             [[synthetic.camera]]\nstream = \"cam\"\nwidth = 800\nheight = 503\nrate_hz = 10.0\nprerender = 10\n\n\
             [[synthetic.lidar]]\nstream = \"lid\"\nrate_hz = 5.0\nprerender = 5\n\n\
             [view]\nport = {port}\nrate_hz = 5.0\ncloud_rate_hz = 5.0\nmax_width = 640\n\
             stats_interval_s = 0.5\nbacklog = 8\n"
        ),
    )
    .unwrap();
    let log = ns.dir.join("bridge.log");
    let report_path = ns.dir.join("bridge-report.json");
    let mut bridge = ns
        .command(exe("perturb-bridge"))
        .arg("--config")
        .arg(&bridge_cfg)
        .arg("--report")
        .arg(&report_path)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .expect("starting perturb-bridge");
    wait_listening(port, &mut bridge, &log);
    let url = format!("ws://127.0.0.1:{port}");

    // The hung viewer first: it subscribes to everything, then stops reading for the whole run.
    let mut hung = Client::start(&client_dir, &url, "hung", &["--stall"]);
    hung.expect("ready", Duration::from_secs(30));
    let mut viewer = Client::start(&client_dir, &url, "viewer", &[]);
    let ready = viewer.expect("ready", Duration::from_secs(30));
    let topics: Vec<&str> = ready["channels"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|c| c["topic"].as_str())
        .collect();
    for t in [
        "/cam/raw/image",
        "/cam/perturbed/image",
        "/lid/raw/points",
        "/lid/perturbed/points",
        "/cam/stats",
        "/lid/stats",
        "/perturb/events",
        "/perturb/status",
    ] {
        assert!(topics.contains(&t), "{t} is not advertised: {ready}");
    }
    let services = ready["services"].to_string();
    for s in [
        "/perturb/set",
        "/perturb/off",
        "/perturb/kill",
        "/perturb/arm",
        "/perturb/status",
    ] {
        assert!(services.contains(s), "{s} is not offered: {ready}");
    }

    // The services change what perturbd applies.
    let r = viewer.call(
        "/perturb/set",
        json!({ "stream": "cam", "id": "C-A1", "severity": 3, "seed": 7 }),
    );
    assert_eq!(r["reply"]["ok"], true, "{r}");
    let cam = status(&ns, "cam");
    assert_eq!(
        (&cam["id"], &cam["severity"], &cam["seed"]),
        (&json!("C-A1"), &json!(3), &json!(7)),
        "{cam}"
    );
    let r = viewer.call(
        "/perturb/set",
        json!({ "stream": "cam", "id": "C-A1", "severity": 9 }),
    );
    assert!(
        r["error"].as_str().is_some_and(|e| e.contains("severity")),
        "a severity of 9 was not refused with the reason: {r}"
    );
    assert_eq!(
        status(&ns, "cam")["severity"],
        3,
        "a refused call changed the stream"
    );
    let r = viewer.call(
        "/perturb/set",
        json!({ "stream": "nope", "id": "C-A1", "severity": 1 }),
    );
    assert!(
        r["error"].is_string(),
        "an unknown stream was accepted: {r}"
    );
    // Frames go out perturbed for a while (the events and stats see them).
    std::thread::sleep(Duration::from_secs(2));
    let r = viewer.call("/perturb/off", json!({ "stream": "cam" }));
    assert_eq!(r["reply"]["ok"], true, "{r}");
    assert_eq!(
        status(&ns, "cam")["id"],
        Value::Null,
        "off did not clear cam"
    );
    let r = viewer.call("/perturb/kill", json!({ "reason": "view test" }));
    assert_eq!(r["reply"]["ok"], true, "{r}");
    for s in ["cam", "lid"] {
        let st = status(&ns, s);
        assert_eq!(st["killed"], true, "kill did not engage the switch: {st}");
    }
    std::thread::sleep(Duration::from_secs(1));
    let r = viewer.call("/perturb/arm", json!({}));
    assert_eq!(r["reply"]["ok"], true, "{r}");
    let lid = status(&ns, "lid");
    assert!(
        lid["killed"] == false && lid["id"] == "L-B1",
        "arm did not release the switch: {lid}"
    );
    let r = viewer.call("/perturb/status", json!({}));
    assert_eq!(r["reply"]["ok"], true, "{r}");
    std::thread::sleep(Duration::from_secs(2));

    // What the viewer received, decoded by the independent libraries.
    let report = viewer.report();
    for (topic, t) in report.as_object().expect("a report object") {
        assert_eq!(
            t["invalid"], 0,
            "{topic}: messages that did not decode: {t}"
        );
    }
    let topic = |t: &str| -> &Value {
        report
            .get(t)
            .unwrap_or_else(|| panic!("the viewer received nothing on {t}: {report}"))
    };
    for side in ["raw", "perturbed"] {
        let t = topic(&format!("/cam/{side}/image"));
        // 800x503 shrunk by 2 to fit max_width = 640.
        assert_eq!(t["images"], json!({ "400x251": t["count"] }), "{t}");
        assert!(t["count"].as_u64().unwrap() >= 5, "{t}");
        assert_eq!(t["last"]["format"], "jpeg", "{t}");
        let t = topic(&format!("/lid/{side}/points"));
        assert!(t["last"]["points"].as_f64().unwrap() > 1000.0, "{t}");
        let fields = t["last"]["fields"].to_string();
        for f in ["\"x\"", "\"y\"", "\"z\""] {
            assert!(fields.contains(f), "{t}");
        }
    }
    for s in ["cam", "lid"] {
        let t = topic(&format!("/{s}/stats"));
        assert!(t["count"].as_u64().unwrap() >= 2, "{t}");
        assert_eq!(t["schema"], "perturb.ViewStats", "{t}");
    }
    assert_eq!(topic("/perturb/status")["last"]["daemon"], "up");
    // The kill and arm records of the view's own calls, valid against the events schema.
    assert!(topic("/perturb/events")["count"].as_u64().unwrap() >= 2);

    // The hung viewer held nothing up: it got less than the live one, and the pipeline lost
    // nothing.
    let stalled = hung.report();
    let n = |r: &Value, t: &str| r[t]["count"].as_u64().unwrap_or(0);
    assert!(
        n(&stalled, "/lid/raw/points") < n(&report, "/lid/raw/points"),
        "the hung client did not fall behind: {stalled}"
    );
    viewer.send(json!({ "cmd": "quit" }));
    let st = perturb_wire::process::interrupt(&mut bridge, Duration::from_secs(15));
    let bridge_log = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        st.is_some_and(|s| s.success()),
        "the bridge did not stop cleanly ({st:?}):\n{bridge_log}"
    );
    drop(hung);
    let frames = sink.finish();
    let daemon_report = daemon.stop();
    for s in daemon_report["streams"].as_array().unwrap() {
        assert_eq!(s["dropped"], 0, "perturbd dropped frames: {s}");
        assert_eq!(s["invalid"], 0, "{s}");
    }
    let seqs: Vec<u64> = frames.iter().map(|f| f.seq).collect();
    assert!(seqs.len() > 40, "the subscriber got {} frames", seqs.len());
    assert!(
        seqs.windows(2).all(|w| w[1] == w[0] + 1),
        "the perturbed stream has gaps: {seqs:?}"
    );
    let bridge_report: Value =
        serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    let view = bridge_report
        .as_array()
        .and_then(|a| {
            a.iter()
                .find(|r| r["name"].as_str().is_some_and(|n| n.starts_with("view")))
        })
        .unwrap_or_else(|| panic!("no view in the bridge's report: {bridge_report}"));
    assert!(view["forwarded"].as_u64().unwrap() > 0, "{view}");
    for r in bridge_report.as_array().unwrap() {
        assert_eq!(r["dropped"], 0, "{r}");
    }
    eprintln!("viewer: {report}");
}

#[test]
fn the_view_shows_a_relayed_camera_info_scaled_to_its_jpeg() {
    if !perturb_tests::have_ros1() {
        return;
    }
    let Some(client_dir) = view_client() else {
        return;
    };
    let ns = Namespace::new("view-caminfo");
    let master = perturb_tests::Ros1Master::start(&ns.dir);
    let port = free_port();
    let cfg = ns.dir.join("bridge.toml");
    // 64x48 frames shrunk by 2 to fit max_width = 32; no perturbd (the local bus): raw side only.
    std::fs::write(
        &cfg,
        format!(
            "[bridge]\nname = \"viewcal\"\nbus = \"local\"\n\n[ros1]\nhostname = \"127.0.0.1\"\n\n\
             [[ingress]]\ntopic = \"/unperturbed/cam/image_raw\"\ntype = \"image\"\nstream = \"cam\"\ntransport = \"ros1\"\n\
             camera_info = \"/unperturbed/cam/camera_info\"\n\n\
             [view]\nport = {port}\nmax_width = 32\ncontrol = false\n"
        ),
    )
    .unwrap();
    let mut bridge = perturb_tests::start_bridge(&ns, Some(&master), &cfg, "bridge.log");
    let log = ns.dir.join("bridge.log");
    wait_listening(port, &mut bridge, &log);
    let mut viewer = Client::start(
        &client_dir,
        &format!("ws://127.0.0.1:{port}"),
        "viewer",
        &[],
    );
    let ready = viewer.expect("ready", Duration::from_secs(30));
    assert!(
        ready["channels"].to_string().contains("/cam/camera_info"),
        "no calibration channel: {ready}"
    );
    let publish = |ty: &str, topic: &str| {
        perturb_tests::ros1_peer(
            &master,
            &[
                "pub", "--topic", topic, "--type", ty, "--count", "30", "--rate", "10", "--size",
                "64x48", "--name", ty,
            ],
        )
    };
    let mut peers = vec![
        publish("image", "/unperturbed/cam/image_raw"),
        publish("camera_info", "/unperturbed/cam/camera_info"),
    ];
    for p in &mut peers {
        let _ = p.wait();
    }
    std::thread::sleep(Duration::from_secs(1));
    let report = viewer.report();
    let st = perturb_wire::process::interrupt(&mut bridge, Duration::from_secs(15));
    assert!(
        st.is_some_and(|s| s.success()),
        "the bridge did not stop cleanly:\n{}",
        std::fs::read_to_string(&log).unwrap_or_default()
    );
    let images = &report["/cam/raw/image"];
    assert_eq!(
        images["images"],
        json!({ "32x24": images["count"] }),
        "{report}"
    );
    let cal = &report["/cam/camera_info"];
    assert_eq!(cal["invalid"], 0, "{cal}");
    assert_eq!(
        (&cal["last"]["width"], &cal["last"]["height"]),
        (&json!(32), &json!(24)),
        "{cal}"
    );
    let k: Vec<f64> = cal["last"]["k"]
        .as_array()
        .unwrap_or_else(|| panic!("no K: {cal}"))
        .iter()
        .filter_map(Value::as_f64)
        .collect();
    // The publisher's K: fx = fy = 500, cx = 32, cy = 24, halved with the image.
    assert_eq!(
        k,
        [250.0, 0.0, 16.0, 0.0, 250.0, 12.0, 0.0, 0.0, 1.0],
        "K is not scaled with the image: {cal}"
    );
}
