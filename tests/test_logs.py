"""setup_script_logging: InputError ends a script with one line (stderr and last log line); bugs keep the traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _script(tmp_path, raise_stmt):
    code = ("from kitegully import InputError\nfrom kitegully.logs import setup_script_logging\n"
            f"log = setup_script_logging({str(tmp_path / 'r.log')!r})\nlog.info('working')\n{raise_stmt}\n")
    env = {**os.environ, "PYTHONPATH": SRC}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)


def test_input_error_is_one_line_and_the_last_line_of_the_log(tmp_path):
    proc = _script(tmp_path, "raise InputError('data/gcp.txt: line 3: non-numeric coordinate')")
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr
    assert proc.stderr.splitlines()[-1] == "data/gcp.txt: line 3: non-numeric coordinate"
    lines = (tmp_path / "r.log").read_text().splitlines()
    assert lines[-1] == "data/gcp.txt: line 3: non-numeric coordinate" and "working" in lines[0]


def test_a_bug_keeps_its_traceback(tmp_path):
    proc = _script(tmp_path, "raise KeyError('bug')")
    assert proc.returncode == 1
    assert "Traceback" in proc.stderr and "KeyError: 'bug'" in proc.stderr
    text = (tmp_path / "r.log").read_text()
    assert "Traceback" in text and "KeyError: 'bug'" in text
