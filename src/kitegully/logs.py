"""Logging for workflow scripts: everything goes to the rule's ``log:`` file.

:func:`setup_script_logging` also installs an exception hook: an :class:`InputError` (bad
user input) ends the script with its one sentence, without a Python traceback, on stderr
and as the last line of the log file; any other exception (a bug) keeps its traceback.
A script that ends without an exception logs its peak memory as its last line
(:func:`peak_memory_line`): the kernel's high-water mark of its resident set, which a
sampling monitor (Snakemake's ``benchmark:`` files sample every 30 s after the first 15 s)
can miss.
"""

from __future__ import annotations

import atexit
import logging
import re
import resource
import sys
from pathlib import Path

from kitegully import InputError

_LOG_PATH: Path | None = None
_FAILED = False
_PEAK_REGISTERED = False
#: The line :func:`peak_memory_line` writes, as :func:`read_peak_memory` parses it.
PEAK_LINE = re.compile(r"peak memory: (\d+) MB resident \(high-water mark\); largest child process (\d+) MB")


def peak_memory_mb() -> tuple[float, float]:
    """Peak resident set size of this process and of its largest finished child (MB).

    Returns
    -------
    self_mb, child_mb : float
        The kernel's high-water marks: this process's, all its threads together, and that of
        the largest child process it has waited for (0 when none).

    Notes
    -----
    [I] On Linux the process's own mark is ``VmHWM`` of ``/proc/self/status``, the peak of
    its address space since ``exec``. ``getrusage``'s ``ru_maxrss`` is not: Linux carries the
    mark of the address space a process was forked or vforked from across ``exec``, so a
    script started by a 1.6 GB pytest worker read 1.6 GB there for a 0.3 GB peak of its own.
    ``ru_maxrss`` serves elsewhere and for the children, whose mark is at least the size this
    process had when it started them (that part never exceeds this process's own peak).
    """
    scale = 1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0  # ru_maxrss: bytes on macOS, KiB on Linux
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / scale
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0, child  # kB
    except (OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale, child


def peak_memory_line() -> str:
    """The log line naming this process's peak memory (see :data:`PEAK_LINE`)."""
    own, child = peak_memory_mb()
    return f"peak memory: {own:.0f} MB resident (high-water mark); largest child process {child:.0f} MB"


def read_peak_memory(log_path: str | Path) -> float | None:
    """The peak memory (MB, the larger of the process and its largest child) a script's log ends with.

    Parameters
    ----------
    log_path : str or Path
        A rule's log file written through :func:`setup_script_logging`.

    Returns
    -------
    float or None
        None when the log holds no peak line (the job failed, or it ran before the line existed).
    """
    try:
        text = Path(log_path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    found = PEAK_LINE.findall(text)
    return max(float(found[-1][0]), float(found[-1][1])) if found else None


def _log_peak_memory() -> None:
    """``atexit``: the peak memory as the log's last line, unless the script ended in an exception."""
    if not _FAILED:
        logging.getLogger("kitegully").info(peak_memory_line())


def _input_error_hook(exc_type, exc, tb) -> None:
    """``sys.excepthook``: one line for InputError, the usual traceback for anything else."""
    global _FAILED
    _FAILED = True  # the error, not the peak memory, stays the log's last line
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
    :class:`InputError` propagate exits with status 1 and one line, the log's last; a script
    that ends normally logs :func:`peak_memory_line` last (at exit).
    """
    global _LOG_PATH, _PEAK_REGISTERED
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    _LOG_PATH = None
    if log_path:
        _LOG_PATH = Path(log_path)
        _LOG_PATH.parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w", encoding="utf-8"))
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s", handlers=handlers, force=True)
    logging.captureWarnings(True)
    sys.excepthook = _input_error_hook
    if not _PEAK_REGISTERED:  # after logging's own atexit shutdown was registered, so it runs before it
        atexit.register(_log_peak_memory)
        _PEAK_REGISTERED = True
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
