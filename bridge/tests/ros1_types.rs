//! The ROS 1 message types of the message-kind table, checked against Debian's rospy message modules:
//! md5sum (what publishers and subscribers compare) and full definition (what `rosbag record`,
//! `rosbags` and Foxglove parse), byte for byte.

mod common;

use common::need;
use perturb_core::formats::{kinds, ros1};
use std::process::Command;

#[test]
fn ros1_msg_types_match_rospy() {
    let python = std::env::var("PERTURB_ROS_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into());
    let names: Vec<String> = kinds::KINDS
        .iter()
        .map(|k| format!("'{}'", k.ros1.name))
        .collect();
    let script = format!("NAMES = [{}]\n", names.join(", "))
        + "import json, importlib\n\
        out = {}\n\
        for name in NAMES:\n\
        \x20   pkg, ty = name.split('/')\n\
        \x20   cls = getattr(importlib.import_module(pkg + '.msg'), ty)\n\
        \x20   out[name] = [cls._md5sum, cls._full_text]\n\
        print(json.dumps(out))\n";
    let o = Command::new(&python).args(["-c", &script]).output();
    let ok = o.as_ref().is_ok_and(|o| o.status.success());
    if !need(
        ok,
        "Debian's ROS 1 message modules (apt-get install python3-sensor-msgs python3-std-msgs python3-rosgraph-msgs)",
    ) {
        return;
    }
    let v: serde_json::Value = serde_json::from_slice(&o.unwrap().stdout).unwrap();
    for k in kinds::KINDS {
        let t = k.ros1;
        let want = &v[t.name];
        assert_eq!(t.md5sum, want[0], "{} md5sum", t.name);
        assert_eq!(t.definition, want[1], "{} definition", t.name);
        assert_eq!(ros1::msg_type(t.ros2_name), Some(t));
    }
}
