//! The Python package `perturb` (`clients/python`): builds its wheel with maturin, installs it
//! into a private virtual environment under the target directory, and runs its pytest suite
//! (`clients/python/tests`): byte identity with `perturb apply` / `perturb detect` on the KITTI
//! data for every perturbation, dtype/shape/stride errors, in-place vs copy, threads, the
//! adapters, and Ray (a local cluster on 127.0.0.1) against `perturb batch`.
//!
//! The extension is built in the `dev` profile (the workspace's: dependencies at opt-level 3,
//! our crates at 1): the bytes do not depend on the optimisation level, and a release build costs
//! minutes on two cores. Cargo rebuilds only what changed; the wheel is reinstalled each run
//! (seconds). Needs maturin, pytest, numpy and ray (`.ci/run` installs them); without them the
//! test is skipped with a message, or fails under `PERTURB_REQUIRE_ORACLES=1` (CI).

use perturb_tests::{exe, have_python_modules, workspace};
use std::io::Write;
use std::path::Path;
use std::process::Command;

fn run(cmd: &mut Command, what: &str) {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    if out.status.success() {
        return;
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // The cause first, on one line: a CI log excerpt may show only the panic's first lines.
    let last = stderr
        .lines()
        .chain(stdout.lines())
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("(no output)");
    let report = format!(
        "{what} failed ({}): {last}\n--- stdout\n{stdout}\n--- stderr\n{stderr}",
        out.status
    );
    // Also straight to the process's stderr, past the test harness's capture: the log then shows
    // the cause where the test runs, before the harness's summary of failures.
    let _ = writeln!(
        std::io::stderr().lock(),
        "python_package_pytest_suite: {report}"
    );
    panic!("{report}");
}

#[test]
fn python_package_pytest_suite() {
    if !have_python_modules(
        "python3",
        &["maturin", "pytest", "numpy", "ray", "PIL"],
        "pip install maturin pytest numpy 'ray[data]' pillow",
    ) {
        return;
    }
    let root = workspace();
    let cli = exe("perturb");
    // target/<profile>/perturb -> target/
    let target = cli
        .parent()
        .and_then(Path::parent)
        .expect("the target directory")
        .to_path_buf();
    let venv = target.join("python-venv");
    let python = venv.join("bin/python");
    if !python.exists() {
        run(
            Command::new("python3")
                .args(["-m", "venv", "--system-site-packages"])
                .arg(&venv),
            "python3 -m venv",
        );
    }
    let wheels = target.join("python-wheels");
    let _ = std::fs::remove_dir_all(&wheels);
    run(
        Command::new("python3")
            .args([
                "-m",
                "maturin",
                "build",
                "--profile",
                "dev",
                "--quiet",
                "-m",
            ])
            .arg(root.join("clients/python/Cargo.toml"))
            .arg("--out")
            .arg(&wheels)
            .arg("--interpreter")
            .arg(&python)
            .env("CARGO_TARGET_DIR", &target),
        "maturin build",
    );
    let wheel = std::fs::read_dir(&wheels)
        .expect("the wheel folder")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .expect("maturin wrote a wheel");
    run(
        Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--no-deps",
                "--force-reinstall",
                "--no-index",
                "--disable-pip-version-check",
            ])
            .arg(&wheel),
        "pip install of the wheel",
    );
    let tmp = target.join("python-tmp");
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).expect("a scratch folder");
    let status = Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "--basetemp"])
        .arg(tmp.join("basetemp"))
        .arg(root.join("clients/python/tests"))
        .env("PERTURB_CLI", &cli)
        .env("RAY_USAGE_STATS_ENABLED", "0")
        .env("NO_ALBUMENTATIONS_UPDATE", "1")
        .current_dir(&tmp)
        .status()
        .expect("running pytest");
    assert!(status.success(), "the pytest suite failed ({status})");
}
