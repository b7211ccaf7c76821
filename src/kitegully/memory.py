"""Process-wide memory allocator settings for the rule scripts that churn large arrays.

A whole-DEM stage (the gully rules at 80 M cells) makes hundreds of temporary arrays of
one DEM's size (320 MB of float32 each). glibc's ``malloc`` gives every block larger
than its mmap threshold (at most 32 MB) fresh pages from the kernel and returns them on
``free``, so every temporary costs the kernel zeroing its pages on first touch: measured
on the gully sensitivity rule at 20 M cells, 6.2–6.6 s of system time next to 10 s of
user time. :func:`keep_freed_memory` raises the mmap and trim thresholds and keeps one
arena, so large blocks come from the heap and freed ones are reused without a page fault
(1.7–2.9 s of system time less per rule there; ``benchmarks/gully_benchmark.py`` reports the
stage's CPU time). The array values are unchanged: this only decides where the memory
comes from.

The price: memory freed inside the heap is not handed back to the system until the
process ends (the rule scripts are short-lived processes) and a freed block can only be
reused by one that fits, so the peak resident size can grow a little (+6 % on that rule).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

log = logging.getLogger(__name__)

# mallopt parameter numbers of glibc's malloc.h
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_ARENA_MAX = -8


def keep_freed_memory(threshold_bytes: int = 2**30) -> bool:
    """Serve blocks up to ``threshold_bytes`` from the heap and keep freed memory for reuse.

    Call once at the start of a process (a rule script), before it starts threads.

    Parameters
    ----------
    threshold_bytes : int
        Blocks below this size come from the heap instead of their own ``mmap``
        ([I] 1 GiB: every float32/float64 raster of an 80 M-cell DEM, 320/640 MB, is
        below it; larger blocks still get their own mapping and go back at ``free``).
        Also the trim threshold: freed heap memory up to this size stays in the process.
        At most 2**31 − 1 (``mallopt`` takes an ``int``).

    Returns
    -------
    bool
        True where glibc accepted the settings; False elsewhere (another C library, e.g.
        musl or macOS: nothing is changed and the process runs as before).

    Notes
    -----
    ``M_ARENA_MAX`` = 1: threads allocate from the main heap too (a thread's own arena
    cannot hold a block larger than 64 MB, so there every large array would be mapped
    afresh again). O(1).
    """
    if not 0 < threshold_bytes < 2**31:
        raise ValueError(f"threshold_bytes must be in (0, 2**31), got {threshold_bytes}")
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        log.info("memory: no glibc mallopt here; allocator left as it is")
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = all(mallopt(p, v) == 1 for p, v in ((_M_ARENA_MAX, 1), (_M_MMAP_THRESHOLD, threshold_bytes),
                                            (_M_TRIM_THRESHOLD, threshold_bytes)))
    log.info("memory: large blocks (< %d MB) served from the heap and reused: %s", threshold_bytes // 2**20, ok)
    return ok
