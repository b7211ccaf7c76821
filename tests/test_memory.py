"""kitegully.memory: the allocator setting of the whole-DEM rule scripts."""

import subprocess
import sys
import textwrap

import pytest

from kitegully.memory import keep_freed_memory

CHILD = textwrap.dedent("""
    import resource, sys
    import numpy as np
    from concurrent.futures import ThreadPoolExecutor
    if sys.argv[1] == "on":
        from kitegully.memory import keep_freed_memory
        assert keep_freed_memory()
    def churn():  # 30 temporaries of 40 MB each, in a thread as the stage's branches
        total = 0.0
        for i in range(30):
            a = np.full(10_000_000, i, np.float32)
            total += float((a * 2)[::100_000].sum())
        return total
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    with ThreadPoolExecutor(1) as pool:
        total = pool.submit(churn).result()
    print(total, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
""")


def _run(mode):
    out = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), int(out[1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt")
def test_keep_freed_memory_reuses_pages_and_keeps_values():
    total_off, faults_off = _run("off")
    total_on, faults_on = _run("on")
    assert total_on == total_off  # the same values: only where the memory comes from changes
    # without it every 40 MB temporary is mapped and zeroed afresh (~600 MB of page faults);
    # with it the freed blocks are reused
    assert faults_on < faults_off / 3, (faults_on, faults_off)


def test_keep_freed_memory_rejects_a_threshold_mallopt_cannot_take():
    with pytest.raises(ValueError, match="threshold_bytes"):
        keep_freed_memory(2**31)
