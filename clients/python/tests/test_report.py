"""``perturb.report`` writes the same study report as ``perturb report``: one page with the
tables it can build and, for each section without its input, the reason."""

import json
import subprocess


def _study(tmp_path):
    study = tmp_path / "study"
    study.mkdir()
    rows = [
        {"id": "C-A1", "name": "gaussian_noise", "severity": s, "frames": 3, "mse": 0.1 * s,
         "max_abs_deviation": 0.3 * s, "jitter_baseline": 0.0, "jitter_perturbed": 0.1}
        for s in (1, 2, 3)
    ]
    (study / "steering.json").write_text(json.dumps({"per_severity": rows, "per_perturbation": []}))
    bench = [
        {"id": "C-A1", "name": "gaussian_noise", "severity": s, "frames": 2, "setup_ms": 0.1,
         "mean_ms": 10.0 * s, "median_ms": 10.0 * s, "p99_ms": 12.0 * s, "max_ms": 12.0 * s,
         "budget_ms": 33.0, "fits_budget": 12.0 * s <= 33.0}
        for s in (1, 2, 3)
    ]
    (study / "bench.json").write_text(json.dumps(bench))
    return study


def test_report_from_python_matches_the_command_line(tmp_path, cli):
    import perturb

    study = _study(tmp_path)
    out = perturb.report(study, tmp_path / "py" / "report.html", title="T")
    assert out["present"] == ["combined", "curves", "latency"]
    assert set(out["missing"]) == {"rq3", "transfer", "hotspots", "rq4"}
    assert "perturb analyze" in out["missing"]["rq3"]
    page = (tmp_path / "py" / "report.html").read_text()
    assert 'id="table-combined-camera"' in page and "C-A1" in page
    # Average latency 20 ms is feasible against 33 ms; the maximum, 36 ms, is not.
    csv = (tmp_path / "py" / "report-combined_camera.csv").read_text().splitlines()
    cells = csv[1].split(",")
    assert cells[0] == "C-A1" and cells[10] == "20" and cells[11] == "36"
    assert cells[14:16] == ["true", "false"]
    subprocess.run(
        [str(cli), "report", str(study), "-o", str(tmp_path / "cli" / "report.html"), "--title", "T"],
        check=True,
        capture_output=True,
    )
    assert (tmp_path / "cli" / "report.html").read_text() == page.replace(
        str(tmp_path / "py"), str(tmp_path / "cli")
    )


def test_a_study_folder_that_does_not_exist_is_an_error(tmp_path):
    import perturb
    import pytest

    with pytest.raises(perturb.PerturbError, match="nowhere"):
        perturb.report(tmp_path / "nowhere", tmp_path / "r.html")
