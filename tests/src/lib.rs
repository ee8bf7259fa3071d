//! # perturb-tests
//!
//! Helpers for the end-to-end tests in `tests/tests/`: every test runs real processes (the test
//! itself as the publisher, `perturbd`, the `perturb-test-sink` subscriber, `perturb ctl`) in an
//! iceoryx2 namespace of its own, so tests neither see each other nor other users of the machine.
//!
//! The binaries of the other crates are found next to the test executable's target directory;
//! build them first (`cargo build --workspace --bins`, the README's test command does).

#[path = "../../bridge/src/bin/common/roscpp.rs"]
mod roscpp;

use perturb_wire::{FrameHeader, TransportOptions};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// What the sink records of each frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Sequence number.
    pub seq: u64,
    /// ROS stamp (sec, nanosec).
    pub stamp: (i32, u32),
    /// `frame_id`.
    pub frame_id: String,
    /// Image width or points per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Image encoding (empty for clouds).
    pub encoding: String,
    /// Applied perturbation ID, severity and seed.
    pub applied: Option<(String, u8, u64)>,
    /// Valid payload bytes.
    pub data_len: u64,
    /// Hop timestamps (ingress, daemon rx, daemon tx), CLOCK_MONOTONIC ns.
    pub hops: (u64, u64, u64),
}

impl FrameRecord {
    /// The record of a received header.
    pub fn from_header(h: &FrameHeader) -> Self {
        FrameRecord {
            seq: h.seq,
            stamp: (h.stamp_sec, h.stamp_nanosec),
            frame_id: h.frame_id().unwrap_or("").to_string(),
            width: h.width,
            height: h.height,
            encoding: h.encoding().unwrap_or("").to_string(),
            applied: h.applied().map(|a| (a.id.to_string(), a.severity, a.seed)),
            data_len: h.data_len,
            hops: (h.t_ingress_ns, h.t_daemon_rx_ns, h.t_daemon_tx_ns),
        }
    }
}

/// A binary of the workspace, next to the test executable's target directory.
pub fn exe(name: &str) -> PathBuf {
    let me = std::env::current_exe().expect("the test executable's path");
    // target/<profile>/deps/<test> or target/<profile>/<bin> -> target/<profile>/<name>
    let mut dir = me.parent().expect("the target directory");
    if dir.ends_with("deps") {
        dir = dir.parent().expect("the target directory");
    }
    let p = dir.join(name);
    assert!(
        p.exists(),
        "{} is missing: build the binaries first (cargo build --workspace --bins)",
        p.display()
    );
    p
}

/// The workspace's root folder.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// A path inside the shared real-data folder (`../shared/data` next to the workspace), or `None`
/// with a message when it is absent. Under `CI=true` an absent path fails the test instead:
/// CI must never pass by skipping the real-data tests.
pub fn shared_data(sub: &str) -> Option<PathBuf> {
    let p = workspace().join("../shared/data").join(sub);
    if p.exists() {
        return Some(p);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "{} is absent and CI=true: the real-data tests need ../shared/data",
        p.display()
    );
    eprintln!("SKIP: {} is absent", p.display());
    None
}

/// A private iceoryx2 namespace and scratch folder for one test; both are removed on drop.
pub struct Namespace {
    /// The transport options every process of the test uses.
    pub options: TransportOptions,
    /// A scratch folder for this test.
    pub dir: PathBuf,
}

impl Namespace {
    /// A namespace named after `tag` (and this process).
    pub fn new(tag: &str) -> Self {
        let options = TransportOptions::isolated(tag);
        let dir = std::env::temp_dir().join(format!("perturb-e2e-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("scratch folder");
        Namespace { options, dir }
    }

    /// A command with the namespace's environment.
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut c = Command::new(program);
        for (k, v) in self.options.to_env() {
            c.env(k, v);
        }
        c
    }

    /// Runs `perturb ctl ARGS` and returns its output.
    pub fn ctl(&self, args: &[&str]) -> Output {
        self.command(exe("perturb"))
            .arg("ctl")
            .args(args)
            .output()
            .expect("running perturb ctl")
    }

    /// `perturb ctl stats --json`, parsed.
    pub fn stats(&self) -> serde_json::Value {
        let out = self.ctl(&["stats", "--json"]);
        assert!(
            out.status.success(),
            "perturb ctl stats failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).expect("stats JSON")
    }

    /// Starts `perturbd --config CONFIG` and waits until it answers `perturb ctl status`.
    pub fn start_daemon(&self, config: &Path) -> Daemon {
        self.start_daemon_with(config, &[])
    }

    /// [`Namespace::start_daemon`] with extra arguments (e.g. `--fresh`).
    pub fn start_daemon_with(&self, config: &Path, extra: &[&str]) -> Daemon {
        let report = self.dir.join("perturbd-report.json");
        // Every start appends to the same log, so a test sees what each daemon said.
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.join("perturbd.log"))
            .expect("daemon log");
        let child = self
            .command(exe("perturbd"))
            .arg("--config")
            .arg(config)
            .arg("--report")
            .arg(&report)
            .args(extra)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("starting perturbd");
        let mut d = Daemon {
            child: Some(child),
            log: self.dir.join("perturbd.log"),
            report,
        };
        let start = Instant::now();
        loop {
            if self.ctl(&["status", "--timeout", "0.5"]).status.success() {
                return d;
            }
            if let Some(st) = d.child.as_mut().and_then(|c| c.try_wait().ok().flatten()) {
                panic!("perturbd exited ({st}) at start:\n{}", d.log_text());
            }
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "perturbd did not answer within 30 s:\n{}",
                d.log_text()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Starts a sink on `stream` of `config` writing to `out`; returns once it is subscribed.
    pub fn start_sink(&self, config: &Path, stream: &str, out: &Path, extra: &[&str]) -> Sink {
        let mut child = self
            .command(exe("perturb-test-sink"))
            .arg("--config")
            .arg(config)
            .arg("--stream")
            .arg(stream)
            .arg("--out")
            .arg(out)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("starting the sink");
        let stdout = child.stdout.take().expect("sink stdout");
        let mut line = String::new();
        BufReader::new(stdout)
            .read_line(&mut line)
            .expect("sink output");
        assert_eq!(line.trim(), "ready", "the sink did not start");
        Sink {
            child,
            out: out.to_path_buf(),
        }
    }
}

impl Drop for Namespace {
    fn drop(&mut self) {
        let _ = self.options.remove_namespace_files();
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// A running `perturbd`; interrupted (SIGINT) on drop.
pub struct Daemon {
    child: Option<Child>,
    /// Its stderr log.
    pub log: PathBuf,
    /// Where it writes its JSON report on exit.
    pub report: PathBuf,
}

impl Daemon {
    /// Its process id, while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(|c| c.id())
    }

    /// The log so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Kills it with SIGKILL (no cleanup, as a crash).
    pub fn kill9(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// Stops it with SIGINT and waits; returns its parsed report.
    pub fn stop(&mut self) -> serde_json::Value {
        if let Some(mut c) = self.child.take() {
            interrupt(&mut c);
        }
        let text = std::fs::read_to_string(&self.report)
            .unwrap_or_else(|e| panic!("no daemon report ({e}):\n{}", self.log_text()));
        serde_json::from_str(&text).expect("report JSON")
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            interrupt(&mut c);
        }
    }
}

/// SIGINT, then SIGKILL after 10 s.
fn interrupt(c: &mut Child) {
    let _ = perturb_wire::process::interrupt(c, Duration::from_secs(10));
}

/// A running sink.
pub struct Sink {
    child: Child,
    /// Its output folder.
    pub out: PathBuf,
}

impl Sink {
    /// Waits for the sink to stop (idle timeout or frame limit) and returns its records.
    pub fn finish(mut self) -> Vec<FrameRecord> {
        let st = self.child.wait().expect("waiting for the sink");
        assert!(st.success(), "the sink failed: {st}");
        self.records()
    }

    /// The records written so far.
    pub fn records(&self) -> Vec<FrameRecord> {
        let text = std::fs::read_to_string(self.out.join("frames.jsonl")).unwrap_or_default();
        text.lines()
            .map(|l| serde_json::from_str(l).expect("a frame record"))
            .collect()
    }

    /// The payload of frame `seq`.
    pub fn payload(&self, seq: u64) -> Vec<u8> {
        std::fs::read(self.out.join(format!("{seq}.bin"))).expect("a recorded payload")
    }

    /// Waits until `n` records are written or `timeout` passes; returns the records.
    pub fn wait_for(&self, n: usize, timeout: Duration) -> Vec<FrameRecord> {
        let start = Instant::now();
        loop {
            let r = self.records();
            if r.len() >= n || start.elapsed() > timeout {
                return r;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Sink {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// True if `python` can import every module of `modules`. When it cannot, the test is skipped
/// with a message naming what is missing and how to install it (`install`), or fails if
/// `PERTURB_REQUIRE_ORACLES=1` (CI).
pub fn have_python_modules(python: &str, modules: &[&str], install: &str) -> bool {
    let missing: Vec<&str> = modules
        .iter()
        .copied()
        .filter(|m| {
            !Command::new(python)
                .args(["-c", &format!("import {m}")])
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .collect();
    if !missing.is_empty() {
        let what = format!("the python module(s) {} ({install})", missing.join(", "));
        assert!(
            std::env::var("PERTURB_REQUIRE_ORACLES").ok().as_deref() != Some("1"),
            "{what} are missing and PERTURB_REQUIRE_ORACLES=1"
        );
        eprintln!("SKIP: {what} are missing");
    }
    missing.is_empty()
}

/// True if the python package `rosbags` (the independent bag reader) can be imported. When it
/// cannot, the test is skipped with a message, or fails if `PERTURB_REQUIRE_ORACLES=1` (CI).
pub fn have_rosbags() -> bool {
    have_python_modules("python3", &["rosbags"], "pip install rosbags")
}

/// Every message of a bag as read by `rosbags` (`bridge/tests/read_bag.py`): topic, type, log
/// time, header stamp and frame_id, geometry, sha256 of the data, or the string.
pub fn read_bag(bag: &Path) -> Vec<serde_json::Value> {
    let o = Command::new("python3")
        .arg(workspace().join("bridge/tests/read_bag.py"))
        .arg(bag)
        .output()
        .expect("running python3");
    assert!(
        o.status.success(),
        "rosbags could not read {}: {}",
        bag.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .skip(1)
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

/// The `/perturb/events` records of a bag read by [`read_bag`].
pub fn events(msgs: &[serde_json::Value]) -> Vec<serde_json::Value> {
    msgs.iter()
        .filter(|m| m["topic"] == "/perturb/events")
        .filter_map(|m| serde_json::from_str(m["string"].as_str()?).ok())
        .collect()
}

/// Debian's ROS 1 packages the ROS 1 tests need (and `.ci/run` installs).
pub const ROS1_PACKAGES: &str = "Debian's ROS 1 packages (apt-get install ros-core python3-rospy python3-rosbag python3-sensor-msgs python3-std-msgs python3-rostopic)";

/// The Python that has Debian's ROS 1 modules (`PERTURB_ROS_PYTHON`, default `/usr/bin/python3`:
/// a virtualenv's or pyenv's Python does not see Debian's packages).
pub fn ros_python() -> String {
    std::env::var("PERTURB_ROS_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into())
}

/// True if `roscore`, `rostopic`, `rosbag` and the rospy message modules are there. When they
/// are not, the test is skipped with a message, or fails if `PERTURB_REQUIRE_ORACLES=1` (CI).
pub fn have_ros1() -> bool {
    let tools = ["roscore", "rostopic", "rosbag"].iter().all(|t| {
        Command::new("sh")
            .args(["-c", &format!("command -v {t}")])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    let modules = Command::new(ros_python())
        .args([
            "-c",
            "import rospy, rosbag, sensor_msgs.msg, std_msgs.msg, rosgraph_msgs.msg",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    let ok = tools && modules;
    if !ok {
        assert!(
            std::env::var("PERTURB_REQUIRE_ORACLES").ok().as_deref() != Some("1"),
            "{ROS1_PACKAGES} are missing and PERTURB_REQUIRE_ORACLES=1"
        );
        eprintln!("SKIP: {ROS1_PACKAGES} are missing");
    }
    ok
}

/// A free TCP port on 127.0.0.1.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// A real `roscore` on 127.0.0.1 on a free port, with a private `ROS_HOME`; stopped on drop.
pub struct Ros1Master {
    /// Its port.
    pub port: u16,
    /// `http://127.0.0.1:PORT/`.
    pub uri: String,
    /// The private ROS_HOME of every process of the test.
    pub home: PathBuf,
    child: Option<Child>,
}

impl Ros1Master {
    /// A master that is not started yet (to start a client before its master).
    pub fn new(dir: &Path) -> Self {
        let port = free_port();
        let home = dir.join("ros_home");
        std::fs::create_dir_all(&home).expect("ROS_HOME");
        Ros1Master {
            port,
            uri: format!("http://127.0.0.1:{port}/"),
            home,
            child: None,
        }
    }

    /// Starts a master in `dir` and waits until it answers.
    pub fn start(dir: &Path) -> Self {
        let mut m = Self::new(dir);
        m.up();
        m
    }

    /// Puts the ROS 1 environment of this master on a command: `ROS_MASTER_URI`,
    /// `ROS_HOSTNAME=127.0.0.1`, the private `ROS_HOME`, no `ROS_IP`.
    pub fn env<'a>(&self, c: &'a mut Command) -> &'a mut Command {
        c.env("ROS_MASTER_URI", &self.uri)
            .env("ROS_HOSTNAME", "127.0.0.1")
            .env("ROS_HOME", &self.home)
            .env("ROS_LOG_DIR", self.home.join("log"))
            .env_remove("ROS_IP")
    }

    /// A command with this master's environment.
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut c = Command::new(program);
        self.env(&mut c);
        c
    }

    /// Starts (or restarts) `roscore -p PORT` and waits until it accepts connections.
    pub fn up(&mut self) {
        use std::os::unix::process::CommandExt;
        assert!(self.child.is_none(), "the master already runs");
        let log = std::fs::File::create(self.home.join("roscore.log")).expect("roscore log");
        let child = self
            .command("roscore")
            .args(["-p", &self.port.to_string()])
            .process_group(0)
            .stdin(Stdio::null())
            .stdout(log.try_clone().expect("log"))
            .stderr(log)
            .spawn()
            .expect("starting roscore");
        self.child = Some(child);
        let start = Instant::now();
        loop {
            if std::net::TcpStream::connect(("127.0.0.1", self.port)).is_ok() {
                break;
            }
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "roscore did not listen on {} within 30 s:\n{}",
                self.port,
                std::fs::read_to_string(self.home.join("roscore.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Stops the master (SIGINT to its process group, SIGKILL after 10 s) and waits until the
    /// port is free.
    // libc's kill on a process group.
    #[allow(unsafe_code)]
    pub fn down(&mut self) {
        if let Some(mut c) = self.child.take() {
            let pgid = c.id() as i32;
            // SAFETY: signalling the process group of a child this helper started.
            unsafe { libc::kill(-pgid, libc::SIGINT) };
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(10) {
                if let Ok(Some(_)) = c.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            // SAFETY: as above; whatever of the group is left (rosmaster, rosout).
            unsafe { libc::kill(-pgid, libc::SIGKILL) };
            let _ = c.wait();
            let start = Instant::now();
            while std::net::TcpStream::connect(("127.0.0.1", self.port)).is_ok()
                && start.elapsed() < Duration::from_secs(10)
            {
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

impl Drop for Ros1Master {
    fn drop(&mut self) {
        self.down();
    }
}

/// A rospy peer (`tests/tests/ros1_peer.py`) with `args`, its stdout piped.
pub fn ros1_peer(master: &Ros1Master, args: &[&str]) -> Child {
    master
        .command(ros_python())
        .arg(workspace().join("tests/tests/ros1_peer.py"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("starting the rospy peer")
}

/// Waits for a rospy subscriber's `{"ready": true}` line; returns the reader of its later lines.
pub fn ros1_ready(child: &mut Child) -> BufReader<std::process::ChildStdout> {
    let mut r = BufReader::new(child.stdout.take().expect("piped stdout"));
    let mut line = String::new();
    r.read_line(&mut line).expect("peer output");
    assert!(
        line.contains("ready"),
        "the rospy subscriber did not start: {line}"
    );
    r
}

/// The JSON lines a rospy peer printed until it exited.
pub fn ros1_lines(mut r: impl BufRead, child: &mut Child) -> Vec<serde_json::Value> {
    let mut out = Vec::new();
    let mut line = String::new();
    while r.read_line(&mut line).is_ok_and(|n| n > 0) {
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line)
            && v.get("ready").is_none()
        {
            out.push(v);
        }
        line.clear();
    }
    let _ = child.wait();
    out
}

/// What the roscpp publisher of the tests needs (Debian's packages).
pub const ROSCPP_PACKAGES: &str =
    "g++ and Debian's roscpp headers (apt-get install g++ libroscpp-dev libsensor-msgs-dev)";

/// The roscpp publisher of the tests (`tests/support/ros1_cpp_pub.cpp`), built once with g++
/// against Debian's roscpp into the target directory (rebuilt when its source is newer). `None`
/// (with a message) when g++ or the headers are missing; a failure under
/// `PERTURB_REQUIRE_ORACLES=1` (CI).
pub fn roscpp_publisher() -> Option<PathBuf> {
    roscpp_program("ros1_cpp_pub")
}

/// `tests/support/<name>.cpp` built with [`roscpp::build`] into `target/roscpp/`.
fn roscpp_program(name: &str) -> Option<PathBuf> {
    let src = workspace().join(format!("tests/support/{name}.cpp"));
    // target/<profile>/perturb -> target/
    let target = exe("perturb")
        .parent()
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .unwrap_or_else(std::env::temp_dir);
    let why = match roscpp::build(&src, &target.join("roscpp")) {
        Ok(bin) => return Some(bin),
        Err(why) => why,
    };
    assert!(
        std::env::var("PERTURB_REQUIRE_ORACLES").ok().as_deref() != Some("1"),
        "{ROSCPP_PACKAGES} are needed and PERTURB_REQUIRE_ORACLES=1: {why}"
    );
    eprintln!("SKIP: {ROSCPP_PACKAGES} are missing: {why}");
    None
}

/// The independent DDS peer (`bridge/tests/dds_peer.py`, Cyclone DDS from the PyPI package
/// `cyclonedds`) with `args`, on loopback, its stdout piped.
pub fn dds_peer(args: &[&str]) -> Child {
    Command::new("python3")
        .arg(workspace().join("bridge/tests/dds_peer.py"))
        .args(args)
        .args(["--interface", "lo"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("starting the DDS peer")
}

/// Reads a peer's JSON lines on a thread of its own until its stdout closes (kill the peer to
/// end it); `{"ready": true}` lines are left out. For subscribers that print while the test
/// goes on: `collect_lines(ros1_ready(&mut sub))`, or `collect_lines(stdout_of(&mut peer))`.
pub fn collect_lines(
    mut r: impl BufRead + Send + 'static,
) -> std::thread::JoinHandle<Vec<serde_json::Value>> {
    std::thread::spawn(move || {
        let mut v = Vec::new();
        let mut line = String::new();
        while r.read_line(&mut line).is_ok_and(|n| n > 0) {
            if let Ok(j) = serde_json::from_str::<serde_json::Value>(&line)
                && j.get("ready").is_none()
            {
                v.push(j);
            }
            line.clear();
        }
        v
    })
}

/// A child's piped stdout, buffered.
pub fn stdout_of(child: &mut Child) -> BufReader<std::process::ChildStdout> {
    BufReader::new(child.stdout.take().expect("piped stdout"))
}

/// Kills the children (the peers of a test) and waits for them.
pub fn kill_all(children: &mut [Child]) {
    for c in children.iter_mut() {
        let _ = c.kill();
    }
    for c in children.iter_mut() {
        let _ = c.wait();
    }
}

/// Starts `perturb-bridge --config CFG` in the namespace (and with the ROS 1 environment of
/// `master`), its log in `ns.dir/LOG`.
pub fn start_bridge(ns: &Namespace, master: Option<&Ros1Master>, cfg: &Path, log: &str) -> Child {
    let log = std::fs::File::create(ns.dir.join(log)).expect("bridge log");
    let mut c = ns.command(exe("perturb-bridge"));
    if let Some(m) = master {
        m.env(&mut c);
    }
    c.arg("--config")
        .arg(cfg)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("starting perturb-bridge")
}

/// Sends a signal to a process (SIGSTOP, SIGCONT, ...).
// libc's kill.
#[allow(unsafe_code)]
pub fn signal(pid: u32, sig: libc::c_int) {
    // SAFETY: signalling a child process this test started.
    unsafe {
        libc::kill(pid as i32, sig);
    }
}

/// The largest gap between consecutive `t_arrival_ns` of `lines`, in ms.
pub fn largest_gap_ms(lines: &[serde_json::Value]) -> f64 {
    let mut t: Vec<u64> = lines
        .iter()
        .filter_map(|g| g["t_arrival_ns"].as_u64())
        .collect();
    t.sort_unstable();
    t.windows(2)
        .map(|w| (w[1] - w[0]) as f64 / 1e6)
        .fold(0.0, f64::max)
}
