//! A sink-only bridge (record or egress, no source in its process) runs until it is stopped; with
//! `[bridge] stop_after_publishers_gone` it stops once the streams it reads have lost their
//! publisher (perturbd) for that long, and says why.

use perturb_tests::{Namespace, exe};
use std::io::Read;
use std::process::Stdio;
use std::time::{Duration, Instant};

#[test]
fn a_recorder_stops_after_perturbd_is_gone_for_the_configured_time_and_not_before() {
    let ns = Namespace::new("sinkstop");
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\nqos = { subscriber_buffer = 8 }\n\
         perturbation = { id = \"C-A1\", severity = 1, seed = 2 }\n",
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let sink_cfg = ns.dir.join("sink.toml");
    let report = ns.dir.join("sink-report.json");
    std::fs::write(
        &sink_cfg,
        format!(
            "[bridge]\nname = \"rec\"\nqos = {{ subscriber_buffer = 8 }}\nstop_after_publishers_gone = 1.0\n\n\
             [record]\nout = \"{}\"\nstreams = [\"cam\"]\nraw = false\nperturbed = true\n\n\
             [streams]\ncam = \"image\"\n",
            ns.dir.join("rec").display()
        ),
    )
    .unwrap();
    let mut sink = ns
        .command(exe("perturb-bridge"))
        .arg("--config")
        .arg(&sink_cfg)
        .arg("--report")
        .arg(&report)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let source_cfg = ns.dir.join("source.toml");
    std::fs::write(
        &source_cfg,
        "[bridge]\nname = \"synth\"\nqos = { subscriber_buffer = 8 }\n\n\
         [[synthetic.camera]]\nstream = \"cam\"\nwidth = 160\nheight = 100\nrate_hz = 20.0\ncount = 10\n",
    )
    .unwrap();
    let o = ns
        .command(exe("perturb-bridge"))
        .arg("--config")
        .arg(&source_cfg)
        .args(["--linger", "1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The source is done but perturbd still publishes the stream: the recorder keeps going.
    std::thread::sleep(Duration::from_secs(3));
    assert!(
        sink.try_wait().unwrap().is_none(),
        "the recorder stopped while perturbd was still up"
    );
    daemon.stop();
    let t = Instant::now();
    let status = loop {
        if let Some(s) = sink.try_wait().unwrap() {
            break Some(s);
        }
        if t.elapsed() > Duration::from_secs(20) {
            let _ = sink.kill();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut log = String::new();
    sink.stderr
        .take()
        .unwrap()
        .read_to_string(&mut log)
        .unwrap();
    assert!(
        status.is_some_and(|s| s.success()),
        "the recorder did not stop after perturbd left: {status:?}\n{log}"
    );
    assert!(
        log.contains("stop_after_publishers_gone"),
        "the recorder did not say why it stopped:\n{log}"
    );
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let rec = rep
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"].as_str().unwrap().starts_with("record"))
        .unwrap_or_else(|| panic!("no recorder in {rep}"));
    assert_eq!(rec["received"], 10, "{rec}");
}

/// More recorders of the same streams than their QoS admits: the ones that fit record, the one
/// that does not says why at once and exits with an error; every one honours `--seconds` (a
/// second recorder used to hang, ignoring `--seconds`, SIGINT and SIGTERM).
#[test]
fn extra_recorders_record_or_stop_at_once_with_a_clear_error() {
    let ns = Namespace::new("recorders");
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\n\
         perturbation = { id = \"C-A1\", severity = 1, seed = 2 }\n",
    )
    .unwrap();
    let _daemon = ns.start_daemon(&daemon_cfg);
    let source_cfg = ns.dir.join("source.toml");
    std::fs::write(
        &source_cfg,
        "[bridge]\nname = \"synth\"\n\n\
         [[synthetic.camera]]\nstream = \"cam\"\nwidth = 160\nheight = 100\nrate_hz = 20.0\n",
    )
    .unwrap();
    let mut source = ns
        .command(exe("perturb-bridge"))
        .arg("--config")
        .arg(&source_cfg)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The raw side admits 4 readers (the daemon and 3 recorders), the fourth recorder is one
    // too many.
    let record = |i: usize| {
        ns.command(exe("perturb-bridge"))
            .args(["record", "--stream", "cam=image", "--seconds", "3", "--out"])
            .arg(ns.dir.join(format!("rec{i}")))
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let mut recs: Vec<_> = (0..3).map(record).collect();
    std::thread::sleep(Duration::from_millis(1500));
    let t = Instant::now();
    let extra = record(3).wait_with_output().unwrap();
    let took = t.elapsed();
    let err = String::from_utf8_lossy(&extra.stderr);
    assert!(
        !extra.status.success(),
        "the extra recorder succeeded:\n{err}"
    );
    assert!(err.contains("as many readers as its QoS allows"), "{err}");
    assert!(
        took < Duration::from_secs(10),
        "the extra recorder took {took:?} to give up"
    );
    for (i, r) in recs.iter_mut().enumerate() {
        let t = Instant::now();
        let status = loop {
            if let Some(s) = r.try_wait().unwrap() {
                break Some(s);
            }
            if t.elapsed() > Duration::from_secs(20) {
                let _ = r.kill();
                break None;
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        let mut log = String::new();
        r.stderr.take().unwrap().read_to_string(&mut log).unwrap();
        assert!(
            status.is_some_and(|s| s.success()),
            "recorder {i} did not stop after --seconds: {status:?}\n{log}"
        );
        assert!(log.contains("recorded for the 3 s asked for"), "{log}");
    }
    let _ = perturb_wire::process::interrupt(&mut source, Duration::from_secs(10));
}
