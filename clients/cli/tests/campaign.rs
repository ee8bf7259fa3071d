//! `perturb campaign check`: the campaign file's checks as a user meets them, and the dry run on
//! a recorded drive (a synthetic rosbag2 bag: 10 m/s along a route of a 100 m straight, a quarter
//! turn and an 80 m straight, poses at 10 Hz): each step switches on and off at the first pose
//! past the arc length or polygon it names.

mod common;
#[path = "../../study/tests/support/mod.rs"]
mod support;

use common::{fails, ok, tmp};
use serde_json::Value;
use support::{Run, route_point, write_route};

fn s(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_dry_run_fires_each_step_at_the_position_it_names() {
    let d = tmp("campaign-dry-run");
    let route = d.join("route.csv");
    write_route(&route);
    let (bag, _) = Run::new("drive", 22.0).write(&d);
    // A square of 10 m around the middle of the turn.
    let (mid, _) = route_point(100.0 + std::f64::consts::PI * 20.0 / 4.0);
    let (x0, y0) = (mid[0] - 5.0, mid[1] - 5.0);
    let campaign = d.join("campaign.toml");
    std::fs::write(
        &campaign,
        format!(
            "name = \"dry\"\n[route]\ncsv = \"route.csv\"\n\
             [[steps]]\nname = \"rain\"\nstreams = [\"cam\"]\nid = \"C-C7\"\nseverity = 2\ntrigger = {{ route = [30.0, 60.0] }}\n\
             [[steps]]\nname = \"fog\"\nstreams = [\"lid\"]\nid = \"L-A9\"\nseverity = 1\n\
             trigger = {{ geofence = [[{x0}, {y0}], [{x1}, {y0}], [{x1}, {y1}], [{x0}, {y1}]] }}\n\
             [[steps]]\nname = \"late\"\nstreams = [\"cam2\"]\nid = \"C-A1\"\nseverity = 1\ntrigger = {{ time = [5.0, 7.5] }}\n\
             [[steps]]\nname = \"by hand\"\nstreams = [\"cam3\"]\nid = \"C-A1\"\nseverity = 1\ntrigger = {{ manual = true }}\n",
            x1 = x0 + 10.0,
            y1 = y0 + 10.0
        ),
    )
    .unwrap();
    let out = ok(&[
        "campaign",
        "check",
        s(&campaign),
        "--bag",
        s(&bag),
        "--pose-topic",
        "/odom",
        "--json",
    ]);
    let v: Value = serde_json::from_str(&out).unwrap();
    let step = |i: usize| &v.as_array().unwrap()[i];
    // Route step: on at the first pose with s >= 30 m, off at the first with s >= 60 m (a pose
    // every metre at 10 m/s and 10 Hz).
    let w = &step(0)["windows"][0];
    let (on, off) = (
        w[0]["arc_length_m"].as_f64().unwrap(),
        w[1]["arc_length_m"].as_f64().unwrap(),
    );
    assert!((30.0..31.0).contains(&on), "on at {on} m");
    assert!((60.0..61.0).contains(&off), "off at {off} m");
    assert_eq!(step(0)["windows"].as_array().unwrap().len(), 1);
    // Geofence step: on at the first pose inside the square, off at the first outside.
    let w = &step(1)["windows"][0];
    for (k, inside) in [(0, true), (1, false)] {
        let (x, y) = (w[k]["x"].as_f64().unwrap(), w[k]["y"].as_f64().unwrap());
        let is_in = x >= x0 && x <= x0 + 10.0 && y >= y0 && y <= y0 + 10.0;
        assert_eq!(is_in, inside, "switch {k} at ({x}, {y})");
    }
    // Time step: from the first pose at or after 5 s to the first at or after 7.5 s.
    let w = &step(2)["windows"][0];
    let (t_on, t_off) = (w[0]["t_s"].as_f64().unwrap(), w[1]["t_s"].as_f64().unwrap());
    assert!(
        (5.0..5.1).contains(&t_on) && (7.5..7.6).contains(&t_off),
        "{t_on} {t_off}"
    );
    assert!(
        step(3)["windows"].as_array().unwrap().is_empty(),
        "manual steps are not dry-run"
    );
    // The text form says it in words.
    let text = ok(&[
        "campaign",
        "check",
        s(&campaign),
        "--bag",
        s(&bag),
        "--pose-topic",
        "/odom",
    ]);
    assert!(text.contains("fires on `perturb ctl next`"), "{text}");
    assert!(text.contains("m along the route"), "{text}");
}

#[test]
fn bad_campaigns_are_refused_naming_the_step_and_field() {
    let d = tmp("campaign-bad");
    let check = |name: &str, body: &str| {
        let p = d.join(name);
        std::fs::write(&p, body).unwrap();
        fails(&["campaign", "check", s(&p)])
    };
    let step = "[[steps]]\nname = \"a\"\nstreams = [\"cam\"]\nid = \"C-C7\"\nseverity = 2\n";
    let e = check(
        "overlap.toml",
        &format!(
            "{step}trigger = {{ time = [0, 10] }}\n[[steps]]\nname = \"b\"\nstreams = [\"cam\"]\nid = \"C-A1\"\nseverity = 1\ntrigger = {{ time = [5, 15] }}\n"
        ),
    );
    assert!(
        e.contains("steps[0] (a) and steps[1] (b) overlap on stream `cam`"),
        "{e}"
    );
    let e = check(
        "poly.toml",
        &format!("{step}trigger = {{ geofence = [[0, 0], [1, 0]] }}\n"),
    );
    assert!(
        e.contains("steps[0] (a).trigger.geofence") && e.contains("at least 3"),
        "{e}"
    );
    let e = check(
        "id.toml",
        &format!(
            "{}trigger = {{ time = [0, 1] }}\n",
            step.replace("C-C7", "C-X1")
        ),
    );
    assert!(e.contains("steps[0] (a).id"), "{e}");
    std::fs::write(d.join("bad.csv"), "x,y\n0,0\n1,nope\n").unwrap();
    let e = check(
        "route.toml",
        &format!("[route]\ncsv = \"bad.csv\"\n{step}trigger = {{ route = [0, 1] }}\n"),
    );
    assert!(e.contains("bad.csv") && e.contains("line 3"), "{e}");
    // The shipped example is valid.
    let example =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/campaign.toml");
    let out = ok(&["campaign", "check", s(&example)]);
    assert!(out.contains("valid"), "{out}");
}
