"""Replay measured job times on a workflow's job graph: the wall time N cores would need.

Issue 21 asks for the whole full-size chain in <= 3 h on 2 cores. A run takes about as
long, so a change to the job graph (which job waits for which) is first checked here,
against the job times a finished run measured, before a whole run is spent on it. This
is an ESTIMATE, not a measurement: it assumes every job takes its measured wall time
whatever runs beside it, one thread per job (``benchmarks/kamech_full.py`` runs that way)
and no scheduling overhead.

Input: the text of ``snakemake -n`` on an empty results folder (every job listed, with
its inputs, outputs, benchmark file and priority) and a ``benchmark.csv`` of a finished
run (``benchmarks/kamech_full.py``; its ``rule`` rows are keyed by the benchmark file's
path under ``benchmarks/``). Jobs without a measured time (local rules, reports) get
``--default-s``. Two list-scheduling policies bracket Snakemake's choice among ready
jobs: ``critical`` (highest priority, then the longest measured path to the end: close
to the best any scheduler can do) and ``listed`` (highest priority, then the dry run's
order).

    .venv/bin/snakemake -n --cores 2 --configfile config/sites/kamech_full.yaml \\
        --config results_dir=/tmp/dry > /tmp/dry.txt
    .venv/bin/python benchmarks/schedule_estimate.py /tmp/dry.txt \\
        docs/benchmarks/kamech_full_sessions15-16.csv --cores 2

O(J log J + E) for J jobs and E dependencies.
"""

from __future__ import annotations

import argparse
import heapq
import re
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

_FIELD = re.compile(r"^\s+(input|output|jobid|benchmark|priority|threads):\s*(.*)$")


@dataclass
class Job:
    """One job of a dry run."""

    rule: str
    jobid: int = -1
    inputs: list[str] = field(default_factory=list)
    outputs: list[str] = field(default_factory=list)
    benchmark: str | None = None
    priority: float = 0.0


def parse_dry_run(text: str) -> list[Job]:
    """The jobs of a ``snakemake -n`` listing (rule blocks), in the listed order."""
    jobs: list[Job] = []
    for line in text.splitlines():
        m = re.match(r"^(?:local)?rule (\w+):$", line)
        if m:
            jobs.append(Job(m.group(1)))
            continue
        f = _FIELD.match(line)
        if not f or not jobs:
            continue
        key, value = f.groups()
        job = jobs[-1]
        if key in ("input", "output"):
            getattr(job, key + "s").extend(v.strip() for v in value.split(",") if v.strip())
        elif key == "jobid":
            job.jobid = int(value)
        elif key == "benchmark":
            job.benchmark = value.strip()
        elif key == "priority":
            job.priority = float("inf") if value.strip() == "highest" else float(value)
    seen: set[int] = set()
    unique = [j for j in jobs if not (j.jobid in seen or seen.add(j.jobid))]  # the summary repeats no block, but be safe
    return unique


def measured_times(benchmark_csv: str | Path) -> dict[str, float]:
    """Wall time (s) by benchmark key, e.g. ``sfm/epoch2/sfm_reconstruct``, from a run's ``rule`` rows."""
    t = pd.read_csv(benchmark_csv)
    t = t[(t["kind"] == "rule") & t["item"].str.endswith(" wall")]
    return {item[: -len(" wall")]: float(v) for item, v in zip(t["item"], t["value"])}


def benchmark_key(path: str) -> str:
    """``.../benchmarks/sfm/epoch2/sfm_reconstruct.tsv`` → ``sfm/epoch2/sfm_reconstruct``."""
    tail = path.split("/benchmarks/", 1)[-1]
    return tail[: -len(".tsv")] if tail.endswith(".tsv") else tail


def dependencies(jobs: list[Job]) -> dict[int, set[int]]:
    """For each job, the jobs whose outputs it reads (by path, or a path inside an output folder)."""
    producer = {o: j.jobid for j in jobs for o in j.outputs}
    deps: dict[int, set[int]] = {j.jobid: set() for j in jobs}
    for j in jobs:
        for i in j.inputs:
            p = producer.get(i)
            if p is None:  # a file inside a folder output
                parent = i
                while "/" in parent and p is None:
                    parent = parent.rsplit("/", 1)[0]
                    p = producer.get(parent)
            if p is not None and p != j.jobid:
                deps[j.jobid].add(p)
    return deps


def simulate(jobs: list[Job], times: dict[int, float], deps: dict[int, set[int]], cores: int,
             policy: str = "critical") -> tuple[float, dict[int, tuple[float, float]]]:
    """Greedy list scheduling of one-thread jobs on ``cores``; returns the makespan and each job's (start, end).

    ``policy``: ``critical`` ranks ready jobs by priority, then by the longest path of
    measured times from the job to the end of the graph; ``listed`` by priority, then
    the dry run's order.
    """
    order = {j.jobid: k for k, j in enumerate(jobs)}
    prio = {j.jobid: j.priority for j in jobs}
    children: dict[int, list[int]] = {j: [] for j in deps}
    for j, ds in deps.items():
        for d in ds:
            children[d].append(j)
    depth: dict[int, int] = {}
    tail: dict[int, float] = {}
    for j in sorted(deps, key=lambda j: -_depth(j, deps, depth)):  # deepest first: children before parents
        tail[j] = times[j] + max((tail[c] for c in children[j]), default=0.0)

    def rank(j: int) -> tuple:
        second = -tail[j] if policy == "critical" else order[j]
        return (-prio[j], second, order[j])

    waiting = {j: set(ds) for j, ds in deps.items()}
    ready = [rank(j) + (j,) for j, ds in waiting.items() if not ds]
    heapq.heapify(ready)
    running: list[tuple[float, int]] = []
    spans: dict[int, tuple[float, float]] = {}
    now = 0.0
    while ready or running:
        while ready and len(running) < cores:
            j = heapq.heappop(ready)[-1]
            spans[j] = (now, now + times[j])
            heapq.heappush(running, (now + times[j], j))
        now, done = heapq.heappop(running)
        for c in children[done]:
            waiting[c].discard(done)
            if not waiting[c]:
                heapq.heappush(ready, rank(c) + (c,))
    return now, spans


def _depth(j: int, deps: dict[int, set[int]], memo: dict[int, int]) -> int:
    """Longest chain of dependencies above job ``j`` (its topological depth)."""
    stack = [j]
    while stack:
        k = stack[-1]
        pending = [d for d in deps[k] if d not in memo]
        if pending:
            stack.extend(pending)
            continue
        memo[k] = 1 + max((memo[d] for d in deps[k]), default=0)
        stack.pop()
    return memo[j]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dry_run", type=Path, help="text of snakemake -n on an empty results folder")
    ap.add_argument("benchmark_csv", type=Path, help="a finished run's benchmark.csv (rule rows)")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--default-s", type=float, default=5.0, help="time of a job with no measured time (s)")
    ap.add_argument("--scale", action="append", default=[], metavar="KEY_SUBSTRING=FACTOR",
                    help="scale the measured time of jobs whose benchmark key contains KEY_SUBSTRING (what-if)")
    a = ap.parse_args()
    jobs = parse_dry_run(a.dry_run.read_text())
    measured = measured_times(a.benchmark_csv)
    scales = [(s.split("=")[0], float(s.split("=")[1])) for s in a.scale]
    times: dict[int, float] = {}
    missing = 0
    for j in jobs:
        key = benchmark_key(j.benchmark) if j.benchmark else None
        t = measured.get(key) if key else None
        if t is None:
            missing += 1
            t = a.default_s
        for sub, f in scales:
            if key and sub in key:
                t *= f
        times[j.jobid] = t
    deps = dependencies(jobs)
    total = sum(times.values())
    print(f"{len(jobs)} jobs ({missing} without a measured time, {a.default_s:.0f} s each), "
          f"{sum(len(d) for d in deps.values())} dependencies, {total:.0f} s of job time "
          f"(>= {total / a.cores:.0f} s on {a.cores} cores)")
    for policy in ("critical", "listed"):
        span, spans = simulate(jobs, times, deps, a.cores, policy)
        busy = total / (a.cores * span)
        print(f"{policy:>8}: {span:.0f} s = {span / 3600:.2f} h on {a.cores} cores ({busy:.0%} busy)")
        longest = sorted(jobs, key=lambda j: -times[j.jobid])[:6]
        print("          longest jobs: " + "; ".join(
            f"{benchmark_key(j.benchmark) if j.benchmark else j.rule} {spans[j.jobid][0]:.0f}-{spans[j.jobid][1]:.0f} s"
            for j in longest))


if __name__ == "__main__":
    main()
