"""Run the workflow from tests: a site file, a results folder under tmp, chosen targets."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SNAKEMAKE = Path(sys.executable).parent / "snakemake"


def run_snakemake(
    site_file: str | Path,
    results_dir: str | Path,
    targets: list[str] | None = None,
    extra: list[str] | None = None,
    cores: int = 1,
    check: bool = True,
) -> subprocess.CompletedProcess:
    """Run snakemake in the repository with ``--configfile site_file`` and a temporary results dir.

    ``results_dir`` overrides ``results_dir`` of config/config.yaml so tests never touch
    ``results/``; the Snakemake metadata folder is put beside it too.
    """
    cmd = [
        str(SNAKEMAKE),
        "--cores", str(cores),
        "--configfile", str(site_file),
        "--config", f"results_dir={results_dir}",
        "--shadow-prefix", str(Path(results_dir) / ".shadow"),
        "--nolock",
        *(extra or []),
        *(targets or []),
    ]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake failed ({proc.returncode}):\n{(proc.stdout + proc.stderr)[-6000:]}")
    return proc
