"""Static check of every Python file of the project with pyflakes.

Session 40 found `make lowcost` broken for a day by a local name shadowing an imported
function (``UnboundLocalError`` at run time); pyflakes reports that, unused imports and
undefined names without running anything.
"""

import io
from pathlib import Path

from pyflakes.api import checkPath
from pyflakes.reporter import Reporter

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("src", "tests", "benchmarks", "workflow/scripts")


def test_pyflakes_finds_nothing():
    out, err = io.StringIO(), io.StringIO()
    files = [p for d in FOLDERS for p in sorted((ROOT / d).rglob("*.py"))]
    assert len(files) > 300
    for f in files:
        checkPath(str(f), Reporter(out, err))
    # rule scripts get the `snakemake` object from Snakemake at run time
    findings = [line for line in (out.getvalue() + err.getvalue()).splitlines()
                if not ("/workflow/scripts/" in line and "undefined name 'snakemake'" in line)]
    assert not findings, "\n".join(findings)
