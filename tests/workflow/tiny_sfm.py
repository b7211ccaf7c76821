"""The tiny twin's SfM rule on a results folder that already holds its flight photos.

Shared by the rerun tests: the twin and flight stages run once per session; every test
copies that folder (times kept, so nothing upstream reruns) and runs only ``sfm_reconstruct``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

from snakemake_utils import REPO, SNAKEMAKE, run_snakemake

SITE_FILE = REPO / "config" / "sites" / "tiny_twin.yaml"
SITE = "tiny_twin"
#: summary.json keys that are wall-clock timings, not numbers of the model
TIMING_KEYS = {"prepare_s", "total_s", "images_per_minute", "features_s", "matching_s", "mapping_s"}


def flight_photos(results: Path) -> Path:
    """Run the twin and flight stages of the tiny twin into ``results``."""
    flight = results / SITE / "flight" / "observed"
    run_snakemake(SITE_FILE, results, [str(flight / "images"), str(flight / "camera_gps.gpx")], cores=2)
    return results


def copy_results(src: Path, dst: Path) -> Path:
    """Copy a results folder keeping modification times (copytree uses copy2)."""
    shutil.copytree(src, dst, symlinks=True)
    return dst


def sfm_command(results: Path, *extra: str) -> list[str]:
    """The snakemake command that makes the tiny twin's SfM summary in ``results``."""
    return [
        str(SNAKEMAKE), "--cores", "2", "--configfile", str(SITE_FILE), "--config", f"results_dir={results}",
        "--shadow-prefix", str(results / ".shadow"), "--nolock", "--rerun-triggers", "mtime", *extra,
        "--", str(results / SITE / "sfm" / "summary.json"),
    ]


def run_sfm(results: Path, *extra: str, check: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.run(sfm_command(results, *extra), cwd=REPO, capture_output=True, text=True, env=env())
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake failed ({proc.returncode}):\n{(proc.stdout + proc.stderr)[-6000:]}")
    return proc


def env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))


def sfm_log(results: Path) -> Path:
    return results / SITE / "logs" / "sfm" / "sfm_reconstruct.log"


def sfm_tables(results: Path) -> dict[str, object]:
    """What a rerun must reproduce: the model files byte for byte, the image table and
    the summary's numbers (its wall-clock timings left out)."""
    sfm = results / SITE / "sfm"
    out: dict[str, object] = {f"model/{p.name}": p.read_bytes() for p in sorted((sfm / "model").iterdir())}
    out["images.csv"] = (sfm / "images.csv").read_text()
    summary = json.loads((sfm / "summary.json").read_text())
    out["summary.json"] = {k: v for k, v in summary.items() if k not in TIMING_KEYS}
    return out
