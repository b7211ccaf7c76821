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
