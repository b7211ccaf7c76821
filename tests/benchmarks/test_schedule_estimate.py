"""benchmarks/schedule_estimate.py: dry-run parsing, dependencies and the list schedule."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import schedule_estimate as se  # noqa: E402

#: a -> b -> d and a -> c (c long), e independent; b reads a file inside a's output folder
DRY = """
Building DAG of jobs...
[Thu Dec  3 06:42:55 2026]
rule a:
    output: /r/s/a_dir
    jobid: 1
    benchmark: /r/s/benchmarks/a.tsv
    threads: 2
[Thu Dec  3 06:42:55 2026]
rule b:
    input: /r/s/a_dir/x.tif
    output: /r/s/b.tif
    jobid: 2
    benchmark: /r/s/benchmarks/b/epoch2/b.tsv
[Thu Dec  3 06:42:55 2026]
rule c:
    input: /r/s/a_dir
    output: /r/s/c.tif, /r/s/c2.tif
    jobid: 3
    benchmark: /r/s/benchmarks/c.tsv
[Thu Dec  3 06:42:55 2026]
localrule d:
    input: /r/s/b.tif, /r/s/elsewhere.csv
    output: /r/s/d.txt
    jobid: 4
[Thu Dec  3 06:42:55 2026]
rule e:
    output: /r/s/e.tif
    jobid: 5
    benchmark: /r/s/benchmarks/e.tsv
    priority: highest
Job stats:
job      count
"""


def test_dry_run_blocks_and_dependencies():
    jobs = se.parse_dry_run(DRY)
    assert [j.rule for j in jobs] == ["a", "b", "c", "d", "e"]
    assert jobs[2].outputs == ["/r/s/c.tif", "/r/s/c2.tif"] and jobs[4].priority == float("inf")
    assert se.benchmark_key(jobs[1].benchmark) == "b/epoch2/b"
    assert se.dependencies(jobs) == {1: set(), 2: {1}, 3: {1}, 4: {2}, 5: set()}


def test_measured_times_read_the_wall_rows(tmp_path):
    csv = tmp_path / "benchmark.csv"
    pd.DataFrame({"kind": ["rule", "rule", "stage"], "item": ["b/epoch2/b wall", "b/epoch2/b CPU", "b wall"],
                  "value": [7.0, 6.0, 99.0]}).to_csv(csv, index=False)
    assert se.measured_times(csv) == {"b/epoch2/b": 7.0}


@pytest.mark.parametrize("policy, cores, span", [("critical", 2, 110.0), ("critical", 1, 150.0), ("listed", 2, 115.0)])
def test_schedule_respects_dependencies_and_cores(policy, cores, span):
    jobs = se.parse_dry_run(DRY)
    times = {1: 10.0, 2: 20.0, 3: 100.0, 4: 5.0, 5: 15.0}
    got, spans = se.simulate(jobs, times, se.dependencies(jobs), cores, policy)
    assert got == pytest.approx(span)
    assert spans[5][0] == 0.0  # the highest priority starts first
    for child, parent in ((2, 1), (3, 1), (4, 2)):
        assert spans[child][0] >= spans[parent][1]


def test_the_critical_policy_starts_the_long_branch_first():
    jobs = se.parse_dry_run(DRY)
    times = {1: 10.0, 2: 20.0, 3: 100.0, 4: 5.0, 5: 15.0}
    deps = se.dependencies(jobs)
    jobs_low = list(jobs)
    jobs_low[4].priority = 0.0  # e no longer first: on one core after a, c (tail 100) before b (tail 25)
    _, spans = se.simulate(jobs_low, times, deps, 1, "critical")
    assert spans[3][0] < spans[2][0]
    _, spans = se.simulate(jobs_low, times, deps, 1, "listed")
    assert spans[2][0] < spans[3][0]
