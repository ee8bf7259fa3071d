//! Builds the small roscpp programs that stand in for a real ROS 1 node in the tests and the
//! `ros1_latency` bench (`tests/support/*.cpp`), with g++ against Debian's roscpp
//! (`libroscpp-dev`, `libsensor-msgs-dev`). Shared by `ros1_latency` and the tests' library.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Builds `src` into `out_dir` (named after the source file, without `.cpp`) unless a binary
/// newer than the source is already there; returns its path, or the compiler's first lines.
pub fn build(src: &Path, out_dir: &Path) -> Result<PathBuf, String> {
    let name = src
        .file_stem()
        .and_then(|s| s.to_str())
        .ok_or_else(|| format!("{}: not a source file", src.display()))?;
    let bin = out_dir.join(name);
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if bin.exists() && modified(&bin) >= modified(src) {
        return Ok(bin);
    }
    std::fs::create_dir_all(out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    // Built under another name and renamed: concurrent users never run a half-written binary.
    let tmp = out_dir.join(format!("{name}.{}", std::process::id()));
    let out = Command::new("g++")
        .args(["-O2", "-o"])
        .arg(&tmp)
        .arg(src)
        .args([
            "-lroscpp",
            "-lrostime",
            "-lroscpp_serialization",
            "-lcpp_common",
            "-lrosconsole",
        ])
        .output()
        .map_err(|e| format!("cannot run g++: {e}"))?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr)
            .lines()
            .take(5)
            .collect::<Vec<_>>()
            .join("\n"));
    }
    std::fs::rename(&tmp, &bin).map_err(|e| format!("installing {}: {e}", bin.display()))?;
    Ok(bin)
}
