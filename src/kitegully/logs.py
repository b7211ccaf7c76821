"""Logging for workflow scripts: everything goes to the rule's ``log:`` file."""

from __future__ import annotations

import logging
import sys
from pathlib import Path


def setup_script_logging(log_path: str | Path | None, name: str = "kitegully") -> logging.Logger:
    """Send the ``kitegully`` logger (and warnings) to ``log_path`` and to stderr."""
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    if log_path:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w", encoding="utf-8"))
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s", handlers=handlers, force=True)
    logging.captureWarnings(True)
    return logging.getLogger(name)
