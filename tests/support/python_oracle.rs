//! Runs an independent Python check (an "oracle": rosbags, mcap, scipy, numpy) from a Rust test.
//! Shared by the test binaries of several crates through `#[path]`, so it needs nothing but std.

use std::process::Command;

/// Runs `python3 -c script args...` and returns its stdout when `modules` (a comma-separated
/// import list) import. When they do not, the check is skipped with a message, or the test fails
/// if `PERTURB_REQUIRE_ORACLES` is set (CI sets it) or `CI=true`, naming `install`. A failing
/// script fails the test with its stderr.
pub fn python_oracle(modules: &str, install: &str, script: &str, args: &[&str]) -> Option<String> {
    let probe = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output();
    if !probe.as_ref().is_ok_and(|o| o.status.success()) {
        assert!(
            std::env::var_os("PERTURB_REQUIRE_ORACLES").is_none()
                && std::env::var("CI").as_deref() != Ok("true"),
            "python modules {modules} are required but missing ({install})"
        );
        eprintln!("skipping the check: python3 -c 'import {modules}' failed ({install})");
        return None;
    }
    let o = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .expect("running python3");
    assert!(
        o.status.success(),
        "python oracle failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    Some(String::from_utf8(o.stdout).expect("the oracle prints UTF-8"))
}
