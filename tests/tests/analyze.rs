//! `perturb analyze` on a real recording: `perturb demo` drives the whole pipeline (synthetic
//! sensors, perturbd switching perturbations, the recorder), and the recording is analysed with
//! the metrics that need no route: its segments per perturbation and their durations, checked
//! against the event times `rosbags` reads from the same bag.

use perturb_tests::{exe, have_rosbags, read_bag};
use serde_json::Value;
use std::process::Command;

#[test]
fn a_demo_recording_is_split_into_its_perturbation_segments() {
    let out = std::env::temp_dir().join(format!("perturb-analyze-demo-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = Command::new(exe("perturb"))
        .args([
            "demo",
            "--seconds",
            "6",
            "--switch-every",
            "2",
            "--width",
            "160",
            "--height",
            "100",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "demo failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let recording = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("recording-")
        })
        .expect("a recording");
    let camera = "/camera_front/perturbed";
    let o = Command::new(exe("perturb"))
        .arg("analyze")
        .arg(&recording)
        .args(["--event-stream", camera, "--min-segment", "0", "--json"])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "analyze failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["errors"].as_array().unwrap().len(), 0, "{v}");
    let run = &v["runs"][0];
    assert_eq!(run["perturbation"], "mixed");
    let segs = v["segments"].as_array().unwrap();
    let labels: Vec<&str> = segs
        .iter()
        .map(|s| s["perturbation"].as_str().unwrap())
        .collect();
    // The demo's camera cycle, in order (6 s at one switch every 2 s: 3 or 4 of them).
    let cycle = ["C-C7", "C-C3", "C-B3", "C-A1"];
    assert!(
        labels.len() >= 3 && labels[..] == cycle[..labels.len()],
        "{labels:?}"
    );
    assert!(segs.iter().all(|s| s["severity"] == 3));
    let total: f64 = segs.iter().map(|s| s["duration_s"].as_f64().unwrap()).sum();
    assert!((total - run["duration_s"].as_f64().unwrap()).abs() < 1e-6);
    for k in ["completion", "cte_avg", "jitter_avg", "coverage_5m"] {
        assert!(
            run[k].is_null(),
            "{k} needs a route, steering or objects: {run}"
        );
    }
    assert!(run["failure"].is_null());
    // Without a route or pose nothing says whether it failed: unjudged, never ok.
    assert_eq!(run["outcome"], "unjudged", "{run}");
    assert!(
        run["unjudged_reason"]
            .as_str()
            .is_some_and(|r| r.contains("pose")),
        "{run}"
    );
    assert_eq!(v["summary"]["unjudged"], 1);
    assert_eq!(v["summary"]["ok"], 0);

    // The recording's MCAP file twice, side by side in a folder: two runs, each as long as
    // the recording, never one merged run.
    let mcap = std::fs::read_dir(&recording)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .expect("the recording's MCAP file");
    let pair = out.join("pair");
    std::fs::create_dir_all(&pair).unwrap();
    for name in ["first.mcap", "second.mcap"] {
        std::fs::copy(&mcap, pair.join(name)).unwrap();
    }
    let o = Command::new(exe("perturb"))
        .arg("analyze")
        .arg(&pair)
        .args(["--event-stream", camera, "--min-segment", "0", "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let pv: Value = serde_json::from_slice(&o.stdout).unwrap();
    let pair_runs = pv["runs"].as_array().unwrap();
    let names: Vec<&str> = pair_runs
        .iter()
        .map(|r| r["run"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["first", "second"], "{pv}");
    for r in pair_runs {
        assert!(
            (r["duration_s"].as_f64().unwrap() - run["duration_s"].as_f64().unwrap()).abs() < 1e-9,
            "{r} vs {run}"
        );
    }

    // The same segments from the event times rosbags reads.
    if !have_rosbags() {
        return;
    }
    let msgs = read_bag(&recording);
    let events: Vec<(u64, Value)> = msgs
        .iter()
        .filter(|m| m["topic"] == "/perturb/events")
        .map(|m| {
            (
                m["log_time"].as_u64().unwrap(),
                serde_json::from_str(m["string"].as_str().unwrap()).unwrap(),
            )
        })
        .collect();
    let t0 = events.iter().map(|e| e.0).min().unwrap();
    let last = events.iter().map(|e| e.0).max().unwrap();
    let mut starts: Vec<(f64, String)> = Vec::new();
    for (t, e) in events.iter().filter(|(_, e)| e["topic"] == camera) {
        let id = e["id"].as_str().unwrap_or("nominal").to_string();
        if starts.last().is_none_or(|s| s.1 != id) {
            let at = if starts.is_empty() {
                0.0
            } else {
                (t - t0) as f64 / 1e9
            };
            starts.push((at, id));
        }
    }
    assert_eq!(starts.len(), segs.len(), "{starts:?}");
    for (s, (at, id)) in segs.iter().zip(&starts) {
        assert_eq!(s["perturbation"].as_str().unwrap(), id);
        assert!(
            (s["start_s"].as_f64().unwrap() - at).abs() < 1e-6,
            "{s} vs {at}"
        );
    }
    let end = segs.last().unwrap()["end_s"].as_f64().unwrap();
    assert!((end - (last - t0) as f64 / 1e9).abs() < 1e-6);
    let _ = std::fs::remove_dir_all(&out);
}
