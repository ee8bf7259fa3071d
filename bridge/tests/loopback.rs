//! DDS pinned to loopback sends nothing anywhere else.
//!
//! Each case runs in a private network namespace (`unshare --net`) holding `lo` and a veth
//! interface `probe0` with an address and multicast on: the kind of interface Cyclone DDS and
//! RustDDS pick by default. Two participants of the bridge's backends (the `dds_latency` writer
//! and its reader child) and the independent Python Cyclone DDS peer exchange images with the
//! test configuration (`interfaces = ["lo"]`, the peer's `--interface lo`); then the kernel's
//! packet counter of `probe0` must still be zero while the frames arrived. A control run without
//! pinning shows the probe does count DDS traffic, so the zero means something. Both runs are
//! repeated with the loopback's MULTICAST flag off (as on most hosts) and on (as in CI's
//! namespace).

mod common;

use common::*;
use std::process::Command;

/// What one run in a namespace saw.
#[derive(Debug)]
struct Run {
    /// Frames the bridge-backend reader received, of those sent.
    received: (usize, usize),
    /// Samples the Python peer received.
    peer: usize,
    /// Packets the kernel sent out of `probe0`.
    probe_tx: u64,
    output: String,
}

fn netns_available() -> bool {
    Command::new("unshare")
        .args(["--net", "true"])
        .status()
        .is_ok_and(|s| s.success())
}

fn run_in_netns(writer: &str, reader: &str, lo_multicast: bool, pinned: bool) -> Run {
    let latency = env!("CARGO_BIN_EXE_dds_latency");
    let peer = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/dds_peer.py");
    let domain = domain(3);
    let (iface, peer_iface) = if pinned {
        ("lo", "--interface lo")
    } else {
        ("default", "")
    };
    let mc = if lo_multicast { "on" } else { "off" };
    let script = format!(
        r#"set -e
ip link set lo up multicast {mc}
ip link add probe0 type veth peer name probe1
# no IPv6 on the probe: the kernel's own router solicitations would count as traffic
sysctl -qw net.ipv6.conf.probe0.disable_ipv6=1 net.ipv6.conf.probe1.disable_ipv6=1
ip link set probe1 up
ip addr add 10.251.0.1/24 dev probe0
ip link set probe0 up multicast on
sleep 0.5
BEFORE=$(sed 's/:/ /' /proc/net/dev | awk '$1 == "probe0" {{ print $11 }}')
{py} {peer} listen --topic /perturb/latency --type image --count 2 --timeout 25 --domain {domain} {peer_iface} > peer.out 2>peer.err &
PEER=$!
sleep 1
{latency} --writer {writer} --reader {reader} --image 64x48 --count 20 --rate 40 --domain {domain} --interface {iface}
wait $PEER || true
echo "peer $(grep -c sha256 peer.out || true)"
AFTER=$(sed 's/:/ /' /proc/net/dev | awk '$1 == "probe0" {{ print $11 }}')
echo "probe_tx $((AFTER - BEFORE))"
"#,
        py = python(),
    );
    let dir = scratch(&format!("netns-{writer}-{reader}-{mc}-{pinned}"));
    let out = Command::new("unshare")
        .args(["--net", "sh", "-c", &script])
        .current_dir(&dir)
        .output()
        .expect("run unshare");
    let text = format!(
        "{}\n{}\npeer stderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
        std::fs::read_to_string(dir.join("peer.err")).unwrap_or_default()
    );
    assert!(out.status.success(), "namespace script failed:\n{text}");
    let field = |key: &str| -> Option<String> {
        text.lines()
            .find_map(|l| l.strip_prefix(key).map(|v| v.trim().to_string()))
    };
    let received = text
        .split_whitespace()
        .zip(text.split_whitespace().skip(1))
        .find(|(_, next)| *next == "received")
        .and_then(|(n, _)| {
            let (a, b) = n.split_once('/')?;
            Some((a.parse().ok()?, b.parse().ok()?))
        })
        .unwrap_or_else(|| panic!("no `N/M received` in:\n{text}"));
    Run {
        received,
        peer: field("peer ").and_then(|v| v.parse().ok()).unwrap_or(0),
        probe_tx: field("probe_tx ")
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no probe counter in:\n{text}")),
        output: text,
    }
}

fn pinned_participants_stay_on_loopback(writer: &str, reader: &str) {
    if !need(
        has_python_module("cyclonedds"),
        "the Python module cyclonedds (pip install cyclonedds)",
    ) || !need(
        has_libddsc(),
        "Cyclone DDS 0.10 libddsc (apt-get install libddsc0debian)",
    ) || !need(
        netns_available(),
        "a private network namespace (`unshare --net`, needs root or user namespaces)",
    ) {
        return;
    }
    for lo_multicast in [false, true] {
        let pinned = run_in_netns(writer, reader, lo_multicast, true);
        assert!(
            pinned.received.0 > 0,
            "lo multicast {lo_multicast}: nothing arrived over loopback:\n{}",
            pinned.output
        );
        assert!(
            pinned.peer > 0,
            "lo multicast {lo_multicast}: the Cyclone peer got nothing over loopback:\n{}",
            pinned.output
        );
        assert_eq!(
            pinned.probe_tx, 0,
            "lo multicast {lo_multicast}: a pinned participant sent on probe0:\n{}",
            pinned.output
        );
    }
    let control = run_in_netns(writer, reader, true, false);
    assert!(
        control.probe_tx > 0,
        "control: unpinned participants sent nothing on probe0, so the probe proves nothing:\n{}",
        control.output
    );
}

#[test]
fn dds_rustdds_pinned_to_loopback_sends_nothing_elsewhere() {
    pinned_participants_stay_on_loopback("rustdds", "rustdds");
}

#[test]
fn dds_cyclone_pinned_to_loopback_sends_nothing_elsewhere() {
    pinned_participants_stay_on_loopback("cyclone", "cyclone");
}
