//! Helpers of the bridge's integration tests: the oracle rule, scratch dirs, processes.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// True when missing oracles must fail the test (CI sets PERTURB_REQUIRE_ORACLES=1).
pub fn required() -> bool {
    std::env::var("PERTURB_REQUIRE_ORACLES").is_ok_and(|v| v == "1")
}

/// Skips (returns false) or fails when `what` is missing, per PERTURB_REQUIRE_ORACLES.
pub fn need(available: bool, what: &str) -> bool {
    if available {
        return true;
    }
    if required() {
        panic!("{what} is missing and PERTURB_REQUIRE_ORACLES=1");
    }
    eprintln!("SKIP: {what} is missing (set PERTURB_REQUIRE_ORACLES=1 to make this a failure)");
    false
}

/// The Python interpreter.
pub fn python() -> String {
    std::env::var("PERTURB_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// True if `python3 -c "import MODULE"` works.
pub fn has_python_module(module: &str) -> bool {
    Command::new(python())
        .args(["-c", &format!("import {module}")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// True if the Cyclone DDS C library (0.10) can be loaded.
pub fn has_libddsc() -> bool {
    perturb_bridge::dds::cyclone::available().is_ok()
}

/// The bridge binary.
pub fn bridge_exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_perturb-bridge"))
}

/// A fresh scratch directory under the target dir.
pub fn scratch(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("bridge-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The shared data folder, if present.
pub fn shared_data(sub: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data")
        .join(sub);
    if p.exists() {
        Some(p)
    } else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{} is absent and CI=true: the real-data tests need ../shared/data",
            p.display()
        );
        eprintln!("SKIP: {} is absent", p.display());
        None
    }
}

/// Sends SIGINT and waits up to `timeout`; kills if it does not stop.
pub fn interrupt(child: &mut Child, timeout: Duration) -> Option<std::process::ExitStatus> {
    perturb_wire::process::interrupt(child, timeout)
}

/// A DDS domain id private to this test process (keeps parallel tests apart).
pub fn domain(offset: u16) -> u16 {
    (std::process::id() % 50) as u16 * 4 + offset + 20
}
