"""Workflow level: a bad GCP file stops the run at check_inputs, in seconds, with the one line last in the log."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1]))

from site_factory import GCP_XYZ, LAT, LON, gcp_lines, make_site  # noqa: E402
from snakemake_utils import REPO, run_snakemake  # noqa: E402


def _site_config(tmp_path: Path, site: dict) -> Path:
    cfg = yaml.safe_load((REPO / "config" / "sites" / "boruszyn_kap.yaml").read_text())
    cfg["site"].update(name="mini", crs="EPSG:32632")
    cfg["inputs"] = {"images_dir": str(site["images"]), "gcp_file": str(site["gcp"]), "checkpoints": None}
    cfg["georef"]["gcp_pixel_scale"] = 1.0
    path = tmp_path / "mini.yaml"
    path.write_text(yaml.safe_dump(cfg), encoding="utf-8")
    return path


def test_bad_gcp_file_stops_at_check_inputs_with_one_line(tmp_path):
    site = make_site(tmp_path / "site")
    rows = [(LON + 1e-4 * i, LAT, z, 10 + 8 * i, 12, f"img_{j}.jpg", f"g{i}") for i, (_, _, z) in enumerate(GCP_XYZ) for j in (0, 1)]
    site["gcp"].write_text(gcp_lines(rows), encoding="utf-8")
    results = tmp_path / "results"
    t0 = time.perf_counter()
    proc = run_snakemake(_site_config(tmp_path, site), results, targets=[str(results / "mini" / "sfm" / "summary.json")],
                         check=False)
    elapsed = time.perf_counter() - t0
    line = (f"{site['gcp']}: GCP coordinates look like degrees (x 9.5 to 9.5003, y 36.9 to 36.9) but EPSG:32632 is in "
            "metres; give projected coordinates or declare the geographic CRS")
    assert proc.returncode != 0
    log = results / "mini" / "logs" / "inputs" / "check_inputs.log"
    assert log.read_text().splitlines()[-1] == line
    assert line in proc.stderr and "Traceback" not in proc.stderr
    assert "Error in rule check_inputs" in proc.stderr
    # onerror repeats it after Snakemake's "Error in rule" block: only Snakemake's closing summary follows
    tail = proc.stderr.split("Error in rule check_inputs")[-1].splitlines()
    k = tail.index(f"rule check_inputs: {line}")
    assert all(ln.startswith(("Complete log", "Elapsed time", "WorkflowError", "At least one job")) for ln in tail[k + 1:] if ln.strip())
    assert not (results / "mini" / "sfm").exists()  # SfM never started
    assert elapsed < 90, elapsed


def test_valid_mini_site_passes_check_inputs(tmp_path):
    site = make_site(tmp_path / "site")
    results = tmp_path / "results"
    run_snakemake(_site_config(tmp_path, site), results, targets=[str(results / "mini" / "inputs" / "report.json")])
    assert (results / "mini" / "inputs" / "gcp_file.txt").read_text() == site["gcp"].read_text()


def test_geographic_site_crs_is_one_line_before_any_job(tmp_path):
    site = make_site(tmp_path / "site")
    path = _site_config(tmp_path, site)
    cfg = yaml.safe_load(path.read_text())
    cfg["site"]["crs"] = "EPSG:4326"
    path.write_text(yaml.safe_dump(cfg))
    proc = run_snakemake(path, tmp_path / "results", extra=["--dry-run"], check=False)
    assert proc.returncode != 0
    assert proc.stderr.strip().splitlines()[-1] == (
        f"Invalid configuration: {path}: site.crs: 'EPSG:4326' is geographic (degrees); give a projected CRS in metres "
        "such as the site's UTM zone (EPSG:326xx north, EPSG:327xx south)")
    assert "Traceback" not in proc.stderr and "Snakefile\", line" not in proc.stderr
    assert not (tmp_path / "results").exists()
