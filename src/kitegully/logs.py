"""Logging for workflow scripts: everything goes to the rule's ``log:`` file.

:func:`setup_script_logging` also installs an exception hook: an :class:`InputError` (bad
user input) ends the script with its one sentence, without a Python traceback, on stderr
and as the last line of the log file; any other exception (a bug) keeps its traceback.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from kitegully import InputError

_LOG_PATH: Path | None = None


def _input_error_hook(exc_type, exc, tb) -> None:
    """``sys.excepthook``: one line for InputError, the usual traceback for anything else."""
    if not issubclass(exc_type, InputError):
        logging.getLogger("kitegully").error("unexpected error (a bug, please report it)", exc_info=(exc_type, exc, tb))
        for h in logging.getLogger().handlers:
            h.flush()
        return
    line = " ".join(str(exc).split())
    for h in logging.getLogger().handlers:
        h.flush()
        if isinstance(h, logging.FileHandler):
            h.close()
    if _LOG_PATH is not None:
        with open(_LOG_PATH, "a", encoding="utf-8") as fh:
            fh.write(line + "\n")
    sys.stderr.write(line + "\n")
    sys.stderr.flush()


def setup_script_logging(log_path: str | Path | None, name: str = "kitegully") -> logging.Logger:
    """Send the ``kitegully`` logger (and warnings) to ``log_path`` and to stderr.

    Installs :func:`_input_error_hook` as ``sys.excepthook`` so a script that lets an
    :class:`InputError` propagate exits with status 1 and one line, the log's last.
    """
    global _LOG_PATH
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    _LOG_PATH = None
    if log_path:
        _LOG_PATH = Path(log_path)
        _LOG_PATH.parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w", encoding="utf-8"))
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s", handlers=handlers, force=True)
    logging.captureWarnings(True)
    sys.excepthook = _input_error_hook
    return logging.getLogger(name)


def failed_job_lines(snakemake_log: str | Path | list) -> list[str]:
    """The last line of each failed job's log, as ``rule <name>: <line>``, from Snakemake's main log.

    Snakemake ends a failed run with its own "Error in rule" blocks; the workflow's
    ``onerror`` handler prints these lines after them, so the console ends with the
    sentence that says what is wrong (an :class:`InputError` is the last line of its
    rule's log; a bug's last line is its exception).

    Parameters
    ----------
    snakemake_log : path or list of paths
        Snakemake's main log file(s) of the run (``onerror``'s ``log``: a list in Snakemake 9).

    Returns
    -------
    list of str
        One line per failed job whose log file exists and is not empty.
    """
    import re

    paths = [snakemake_log] if isinstance(snakemake_log, (str, Path)) else list(snakemake_log or [])
    text = ""
    for p in paths:
        try:
            text += Path(p).read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
    out = []
    for block in re.split(r"(?m)^.*Error in rule ", text)[1:]:
        rule = block.split(":", 1)[0].strip()
        m = re.search(r"(?m)^\s*log:\s*(\S+)", block)
        if not m:
            continue
        path = Path(m.group(1))
        try:
            lines = [ln for ln in path.read_text(encoding="utf-8", errors="replace").splitlines() if ln.strip()]
        except OSError:
            continue
        if lines:
            line = f"rule {rule}: {lines[-1].strip()}"
            if line not in out:
                out.append(line)
    return out
