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


def test_failed_job_lines_name_each_failed_rule_and_its_last_log_line(tmp_path):
    from kitegully.logs import failed_job_lines

    good = tmp_path / "a.log"
    good.write_text("2026 INFO start\n/data/gcp.txt: heights look like feet\n")
    main = tmp_path / "snakemake.log"
    main.write_text(f"Error in rule check_inputs:\n    jobid: 1\n    log: {good} (check log file(s) for error details)\n"
                    f"[date]\nError in rule sfm:\n    log: {tmp_path / 'absent.log'}\n")
    assert failed_job_lines([str(main)]) == ["rule check_inputs: /data/gcp.txt: heights look like feet"]
    assert failed_job_lines(tmp_path / "none.log") == []


def test_a_script_that_ends_normally_logs_its_peak_memory_last(tmp_path):
    from kitegully.logs import read_peak_memory

    # 300 MB touched: the high-water mark must hold it even though the array is freed before exit
    proc = _script(tmp_path, "import numpy as np\na = np.ones(300 * 2**20 // 8)\ndel a")
    assert proc.returncode == 0, proc.stderr
    lines = (tmp_path / "r.log").read_text().splitlines()
    assert "peak memory:" in lines[-1] and "working" in lines[0]
    assert 300 <= read_peak_memory(tmp_path / "r.log") < 1000


def test_no_peak_line_after_an_input_error_or_a_bug(tmp_path):
    from kitegully.logs import read_peak_memory

    for stmt in ("raise InputError('a.tif: no CRS')", "raise KeyError('bug')"):
        _script(tmp_path, stmt)
        assert read_peak_memory(tmp_path / "r.log") is None
    assert read_peak_memory(tmp_path / "absent.log") is None


def test_the_peak_is_the_scripts_own_not_its_launchers(tmp_path):
    from kitegully.logs import read_peak_memory

    # a 600 MB launcher (as Snakemake or a pytest worker) starts a script that needs 50 MB:
    # Linux carries the launcher's mark in ru_maxrss across exec; the stated peak must not
    script = ("from kitegully.logs import setup_script_logging\n"
              f"setup_script_logging({str(tmp_path / 's.log')!r}).info('small job')\n")
    launcher = ("import os, subprocess, sys\nimport numpy as np\na = np.ones(600 * 2**20 // 8)\n"
                f"subprocess.run([sys.executable, '-c', {script!r}], check=True)\n")
    env = {**os.environ, "PYTHONPATH": SRC}
    subprocess.run([sys.executable, "-c", launcher], check=True, env=env)
    assert read_peak_memory(tmp_path / "s.log") < 400
