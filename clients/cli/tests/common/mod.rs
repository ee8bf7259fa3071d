//! Helpers shared by the `perturb` binary's integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs `perturb ARGS`.
pub fn perturb(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_perturb"))
        .args(args)
        .output()
        .expect("run perturb")
}

/// Runs `perturb ARGS`, which must succeed; its stdout.
pub fn ok(args: &[&str]) -> String {
    let o = perturb(args);
    assert!(
        o.status.success(),
        "perturb {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// Runs `perturb ARGS`, which must fail; its stderr.
pub fn fails(args: &[&str]) -> String {
    let o = perturb(args);
    assert!(!o.status.success(), "perturb {args:?} should fail");
    String::from_utf8(o.stderr).unwrap()
}

/// The shared data folder, or None (with a skip message) when it is absent.
pub fn shared(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("PERTURB_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{test}: real data not found at {} and CI=true (set PERTURB_SHARED_DATA)",
            dir.display()
        );
        eprintln!("skipping {test}: real data not found at {}", dir.display());
        None
    }
}

/// A scratch directory removed when the test ends (kept when PERTURB_KEEP_TEST_FILES is set).
pub struct Tmp(pub PathBuf);

impl Drop for Tmp {
    fn drop(&mut self) {
        if std::env::var_os("PERTURB_KEEP_TEST_FILES").is_none() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl std::ops::Deref for Tmp {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

/// A fresh scratch directory for test `name`.
pub fn tmp(name: &str) -> Tmp {
    let d = std::env::temp_dir().join(format!("perturb-cli-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    Tmp(d)
}
