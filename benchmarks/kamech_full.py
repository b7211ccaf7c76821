"""The whole Kamech survey at full size (issue 21): run it, then tabulate cost and accuracy.

Runs Snakemake on ``config/sites/kamech_full.yaml`` (3.18 km², ~770 photos per epoch, both
epochs, every stage) and writes ``results/<site>/benchmark.csv`` (+ ``.md``):

- ``rule`` rows: per Snakemake job, wall time, CPU time and peak memory (max RSS) from the
  rules' benchmark files (``results/<site>/benchmarks/**.tsv``);
- ``stage`` rows: the same summed per stage (jobs, wall, CPU, largest peak);
- ``run`` rows: total wall time of the Snakemake run, the largest peak memory of any job,
  the number of jobs;
- ``accuracy`` rows: camera RMSE, checkpoint mean / SD / n (both epochs), DSM coverage, gully
  good fit / FP / FN at 5 m, polygon IoU (the polygon issue's metric, gullies wider than 2 m,
  and the median over gullies), width / depth errors and volume error, change net error,
  headcut retreat error, bare-soil OA, each next to the paper's Tables 3-4 value (Feurer et
  al. 2018) where the paper gives one, and the issues' targets;
- ``scaling`` rows: the tiled stages (gully depth tiles + mosaic, fill tiles + merge +
  mosaic) rerun with ``--cores 1`` and ``--cores 2`` in the same session, and the speed-up
  (each wall time includes Snakemake's start, a few seconds).

    .venv/bin/python benchmarks/kamech_full.py [--cores 2]             # the full site (hours)
    .venv/bin/python benchmarks/kamech_full.py --cut 600x400 --tile-m 200  # a cut-down extent
    .venv/bin/python benchmarks/kamech_full.py --collect-only          # re-tabulate a finished run
    .venv/bin/python benchmarks/kamech_full.py --scaling-only --scaling-rules gully_depth_tile gully_fill_tile
                                            # the speed-up alone, on a finished run, for some tile rules
    .venv/bin/python benchmarks/kamech_full.py --dry-run               # snakemake -n

The per-job rows are read before the scaling reruns, which overwrite the tile jobs' benchmark
files: a later ``--collect-only`` reports those jobs' 2-core rerun instead.

``--cut WxH`` runs the same site on a W × H m corner (site name ``kamech_full_cut<W>x<H>``,
its own results folder); every row of its table says ``NOT the full site``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.io.tables import write_table  # noqa: E402

SITE_FILE = REPO / "config/sites/kamech_full.yaml"
SNAKEMAKE = REPO / ".venv/bin/snakemake"
#: Tile jobs rerun for the 1- vs 2-core speed-up, and the merge rules they run until.
#: Dense matching's tile jobs are left out: rerunning both epochs twice would add more than an hour.
TILE_RULES = ("gully_depth_tile", "gully_fill_tile", "polygons_morph_tile", "obia_kite_tile", "change_tile")
MERGE_RULES = ("gully_depth_mosaic", "gully_fill_mosaic", "polygons_morph_merge", "obia_kite_merge", "change_merge")
MERGE_OF = dict(zip(TILE_RULES, MERGE_RULES))

#: Rules that claim two threads in the workflow, run on one each here (see ``base`` in main).
ONE_THREAD_RULES = ("twin_epoch1", "twin_epoch2", "flight_render", "sfm_reconstruct", "georef_adjust", "dense_tile",
                    "dense_match", "dense_finish", "ortho_tile", "gully_map", "gully_sensitivity", "gully_trace_surface",
                    "obia_classify", "obia_scene", "obia_kite_scale", "closerange_photos")
#: (item, unit, paper value, issue target): Feurer et al. 2018 Tables 3-4 (METHODS.md 1.8).
PAPER = {
    "camera RMSE": ("m", None, "<= 2 GSD"),
    "checkpoint mean": ("m", 0.06, None),
    "checkpoint SD": ("m", 0.22, "<= 1.5 GSD"),
    "checkpoint n": ("", 469, None),
    "DSM valid": ("%", None, None),
    "gully good fit 5 m": ("%", 74.0, ">= 85"),
    "gully FP 5 m": ("%", 8.0, None),
    "gully FN 5 m": ("%", 26.0, None),
    "polygon IoU, gullies wider than 2 m": ("", None, ">= 0.6"),
    "polygon IoU (median over gullies)": ("", None, None),
    "polygon width median abs error": ("m", None, "<= 1"),
    "polygon depth median abs error": ("m", None, "<= 0.15"),
    "polygon volume error": ("%", None, "|.| <= 15"),
    "checkpoint mean, epoch 2": ("m", None, None),
    "checkpoint SD, epoch 2": ("m", None, "<= 1.5 GSD"),
    "checkpoint n, epoch 2": ("", None, None),
    "headcut retreat median abs error": ("m", None, "<= 0.5"),
    "change net error": ("%", None, "|.| <= 10"),
    "kite bare-soil OA": ("%", None, None),
    "GSD": ("m", 0.13, None),
    "images epoch 1": ("", 752, None),
}


def snakemake(args: list[str], log_path: Path, env: dict) -> float:
    """Run Snakemake from the repository root; return its wall time (s)."""
    log_path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with open(log_path, "w") as fh:
        rc = subprocess.call([str(SNAKEMAKE), *args], cwd=REPO, stdout=fh, stderr=subprocess.STDOUT, env=env)
    wall = time.perf_counter() - t0
    if rc:
        raise SystemExit(f"snakemake failed (exit {rc}): see {log_path}")
    return wall


def rule_costs(site_dir: Path) -> pd.DataFrame:
    """One row per benchmark file: job, wall s, CPU s, peak RSS MB."""
    rows = []
    for p in sorted((site_dir / "benchmarks").rglob("*.tsv")):
        b = pd.read_csv(p, sep="\t")
        if b.empty:
            continue
        rows.append({"job": str(p.relative_to(site_dir / "benchmarks").with_suffix("")),
                     "wall_s": float(b["s"].iloc[-1]), "cpu_s": float(b["cpu_time"].iloc[-1]),
                     "max_rss_mb": float(b["max_rss"].iloc[-1])})
    return pd.DataFrame(rows, columns=["job", "wall_s", "cpu_s", "max_rss_mb"])


def log_peaks(site_dir: Path) -> pd.DataFrame:
    """One row per rule log that ends with a peak-memory line: job, peak MB (the kernel's high-water mark).

    Snakemake's benchmark files sample a job's memory every 30 s after its first 15 s, so a
    shorter peak falls between samples (session 18: 6.0 GB in the files, 11.3 GB by
    ``time -v`` around the run). Every rule script logs its process's high-water mark at exit
    (``VmHWM``, :func:`kitegully.logs.peak_memory_line`), whether or not its rule has a benchmark file.

    Parameters
    ----------
    site_dir : Path
        ``results/<site>``; its ``logs/**/*.log`` are read.

    Returns
    -------
    DataFrame
        ``job, peak_mb`` (job = the log's path under ``logs/`` without ``.log``), largest first.
    """
    from kitegully.logs import read_peak_memory

    rows = [{"job": str(p.relative_to(site_dir / "logs").with_suffix("")), "peak_mb": peak}
            for p in sorted((site_dir / "logs").rglob("*.log")) if (peak := read_peak_memory(p)) is not None]
    out = pd.DataFrame(rows, columns=["job", "peak_mb"])
    return out.sort_values("peak_mb", ascending=False, ignore_index=True)


def stage_costs(costs: pd.DataFrame) -> pd.DataFrame:
    """Per stage (the first folder of a job's benchmark file): jobs, summed wall and CPU s, largest peak MB.

    Parameters
    ----------
    costs : DataFrame
        :func:`rule_costs`.

    Returns
    -------
    DataFrame
        ``stage, jobs, wall_s, cpu_s, max_rss_mb``, one row per stage in order of summed wall time.
    """
    if costs.empty:
        return pd.DataFrame(columns=["stage", "jobs", "wall_s", "cpu_s", "max_rss_mb"])
    stage = costs["job"].str.split("/").str[0]
    out = costs.groupby(stage).agg(jobs=("job", "size"), wall_s=("wall_s", "sum"), cpu_s=("cpu_s", "sum"),
                                   max_rss_mb=("max_rss_mb", "max"))
    return out.rename_axis("stage").reset_index().sort_values("wall_s", ascending=False, ignore_index=True)


def _kv(path: Path, key_col: str, val_col: str) -> dict:
    if not path.exists():
        return {}
    d = pd.read_csv(path)
    return dict(zip(d[key_col].astype(str), d[val_col]))


def accuracies(site_dir: Path) -> dict[str, float]:
    """The products' accuracies (whatever of them the run made)."""
    out: dict[str, float] = {}
    ev = site_dir / "georef/twin_evaluation.json"
    if ev.exists():
        j = json.loads(ev.read_text())
        out["camera RMSE"] = j.get("camera_rmse_m")
        out["GSD"] = j.get("gsd_m")
        out["images epoch 1"] = j.get("n_images")
    cp = _kv(site_dir / "validate/checkpoint_summary.csv", "statistic", "value_m")
    for k, name in (("mean", "checkpoint mean"), ("sd", "checkpoint SD"), ("n", "checkpoint n")):
        if k in cp:
            out[name] = cp[k]
    ds = _kv(site_dir / "dense/dense_summary.csv", "quantity", "value")
    if "valid_pct" in ds:
        out["DSM valid"] = ds["valid_pct"]
    nv = _kv(site_dir / "gully/network_validation.csv", "category", "percent")
    for k, name in (("good_fit", "gully good fit 5 m"), ("false_positive", "gully FP 5 m"), ("false_negative", "gully FN 5 m")):
        if k in nv:
            out[name] = nv[k]
    cp2 = _kv(site_dir / "validate/epoch2/checkpoint_summary.csv", "statistic", "value_m")
    for k, name in (("mean", "checkpoint mean, epoch 2"), ("sd", "checkpoint SD, epoch 2"), ("n", "checkpoint n, epoch 2")):
        if k in cp2:
            out[name] = cp2[k]
    ps = site_dir / "polygons/polygon_scores.csv"
    if ps.exists():
        scores = pd.read_csv(ps)
        per_gully = scores[scores["gully_id"] >= 0]
        wide = scores[scores["kind"] == "wide"]
        if len(wide):  # the metric: the cells of all gullies wider than 2 m together
            out["polygon IoU, gullies wider than 2 m"] = float(wide["iou"].iloc[0])
        out["polygon IoU (median over gullies)"] = float(per_gully["iou"].median())
    me = site_dir / "polygons/morphometry_errors.csv"
    if me.exists():
        err = pd.read_csv(me).set_index("quantity")
        for q, name in (("width (m)", "polygon width median abs error"), ("depth (m)", "polygon depth median abs error")):
            if q in err.index:
                out[name] = float(err.loc[q, "median_abs_error"])
        q = "volume, all sections vs all true gullies (m3)"
        if q in err.index:
            out["polygon volume error"] = float(err.loc[q, "error_pct"])
    ch = _kv(site_dir / "change/evaluation_summary.csv", "quantity", "value")
    if "site_net_error_pct" in ch:
        out["change net error"] = ch["site_net_error_pct"]
    key = "headcut median |error| (heads that retreated)"
    if key in ch:
        out["headcut retreat median abs error"] = ch[key]
    ob = site_dir / "obia/kite/accuracy.csv"
    if ob.exists():
        out["kite bare-soil OA"] = float(pd.read_csv(ob)["overall_accuracy"].iloc[0])
    return out


def keep_below_target(site_dir: Path, acc: dict[str, float], target_pct: float = 85.0) -> Path | None:
    """Copy epoch 1's DSM, orthophoto and gully tables aside when the network misses its target.

    Session 18's run scored 79.5 % and its DSM was overwritten by the next run before anyone
    could ask why; a run that misses the target now keeps what the miss analysis needs
    (``benchmarks/gully_miss_analysis.py`` on a site folder holding these as ``dense/`` and
    ``gully/``, with the twin's ``twin/`` beside them) under ``kept_below_target/<UTC time>/``.
    Returns that folder, or None when nothing was kept.
    """
    good = acc.get("gully good fit 5 m")
    if good is None or not np.isfinite(good) or good >= target_pct:
        return None
    dest = site_dir / "kept_below_target" / time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    for rel in ("dense/dsm.tif", "dense/orthophoto.tif", "gully/gully_summary.csv", "gully/network_validation.csv"):
        src = site_dir / rel
        if src.exists():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / rel)
    print(f"gully good fit {good:.1f} % < {target_pct:.0f} %: the DSM and gully tables were kept in {dest}")
    return dest


def wall_from_log(log_path: Path) -> float | None:
    """Seconds a Snakemake run took, from its log (None when the log cannot say).

    Parameters
    ----------
    log_path : Path
        Snakemake's output (``benchmark_run.log``, a resumed run's ``benchmark_run2.log``).

    Returns
    -------
    float or None
        From the ``Date:`` of Snakemake's header (its start, to the second) to the log's last
        write (its end, or the moment an interrupted run was stopped); without the header,
        the span of the job timestamps (``[Tue Dec  1 23:54:43 2026]``). For a run whose
        wrapper did not time it.
    """
    if not log_path.exists():
        return None
    text = log_path.read_text()
    head = re.search(r"^\s*Date: (\d{4}-\d\d-\d\d \d\d:\d\d:\d\d)", text, re.M)
    if head:
        start = datetime.strptime(head.group(1), "%Y-%m-%d %H:%M:%S")
        return (datetime.fromtimestamp(log_path.stat().st_mtime) - start).total_seconds()
    stamps = [datetime.strptime(" ".join(m.group(1).split()), "%a %b %d %H:%M:%S %Y")
              for m in re.finditer(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$", text, re.M)]
    return (max(stamps) - min(stamps)).total_seconds() if len(stamps) >= 2 else None


def run_log(site_dir: Path) -> Path:
    """The log for the next Snakemake run: ``benchmark_run.log``, or the first free ``benchmark_run<N>.log``.

    An interrupted run's log is kept (its span counts in the total wall time of the resumed run).
    """
    path = site_dir / "benchmark_run.log"
    n = 2
    while path.exists():
        path = site_dir / f"benchmark_run{n}.log"
        n += 1
    return path


def timed_rows(table: Path) -> list[tuple]:
    """The Snakemake wall-time rows of an earlier benchmark table (``--collect-only`` keeps them).

    Parameters
    ----------
    table : Path
        ``benchmark.csv`` of an earlier run; absent = nothing to keep.

    Returns
    -------
    list of tuple
        (kind, item, value, unit, paper, target) of its ``scaling`` rows and its ``run`` row of
        the total wall time: measured only while Snakemake ran, so a re-tabulation must not drop them.
    """
    if not table.exists():
        return []
    old = pd.read_csv(table)
    keep = (old["kind"] == "scaling") | ((old["kind"] == "run") & old["item"].str.startswith("total wall"))
    cols = ["kind", "item", "value", "unit", "paper", "target"]
    return [tuple(None if pd.isna(v) else v for v in r) for r in old.loc[keep, cols].itertuples(index=False)]


def scaling_targets(tile_rules: list[str] | None) -> tuple[list[str], list[str]]:
    """The tile rules to rerun for the 1- vs 2-core ratio and the merge rules they run until.

    Parameters
    ----------
    tile_rules : list of str or None
        A subset of :data:`TILE_RULES` (None = all of them).

    Returns
    -------
    (list of str, list of str)
        The tile rules, in :data:`TILE_RULES` order, and their merges.
    """
    chosen = list(TILE_RULES) if not tile_rules else [r for r in TILE_RULES if r in tile_rules]
    unknown = sorted(set(tile_rules or ()) - set(TILE_RULES))
    if unknown:
        raise SystemExit(f"--scaling-rules: {', '.join(unknown)} is not a tile rule (one of {', '.join(TILE_RULES)})")
    return chosen, [MERGE_OF[r] for r in chosen]


def scaling_label(tile_rules: list[str], k: int) -> str:
    """The table's item for the tiled stages' rerun on ``k`` cores (names the rules when not all)."""
    which = ("gully depth + fill, polygon morphometry, kite map, change" if list(tile_rules) == list(TILE_RULES)
             else " + ".join(tile_rules))
    return f"tiled stages ({which}: tile jobs and merges), --cores {k}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--cut", help="run a W x H m corner instead of the full site, e.g. 600x400 (NOT the full site)")
    ap.add_argument("--tile-m", type=float, help="tiling.tile_m override (with --cut: keep several tiles)")
    ap.add_argument("--results-dir", default="results")
    ap.add_argument("--collect-only", action="store_true")
    ap.add_argument("--dry-run", action="store_true")
    ap.add_argument("--no-scaling", action="store_true", help="skip the 1- vs 2-core rerun of the tiled stages")
    ap.add_argument("--scaling-only", action="store_true",
                    help="only the 1- vs 2-core reruns on a finished run's results, then re-tabulate")
    ap.add_argument("--scaling-rules", nargs="+", metavar="RULE",
                    help=f"rerun only these tile rules for the speed-up (default: all of {', '.join(TILE_RULES)})")
    ap.add_argument("--mtime-only", action="store_true",
                    help="resume without rerunning finished jobs whose code or params changed since (--rerun-triggers mtime)")
    args = ap.parse_args()

    site_cfg = yaml.safe_load(SITE_FILE.read_text())
    site = site_cfg["site"]["name"]
    configfiles = [str(SITE_FILE)]
    label = "full site (3.18 km2)"
    override: dict = {}
    if args.cut:
        w, h = (float(v) for v in args.cut.lower().split("x"))
        site = f"kamech_full_cut{int(w)}x{int(h)}"
        ext = dict(site_cfg["twin"]["extent"], width_m=w, height_m=h)
        override = {"site": dict(site_cfg["site"], name=site), "twin": {"extent": ext}}
        label = f"NOT the full site: {w:.0f} x {h:.0f} m = {w * h / 1e6:.3f} km2 corner"
    if args.tile_m:
        override.setdefault("tiling", {})["tile_m"] = args.tile_m
    results = Path(args.results_dir).resolve()
    site_dir = results / site
    if override:
        ov = results / f"{site}.override.yaml"
        ov.parent.mkdir(parents=True, exist_ok=True)
        ov.write_text(yaml.safe_dump(override, sort_keys=False))
        configfiles.append(str(ov))
    env = dict(os.environ, PYTHONPATH=f"{REPO / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    # a run of hours may be interrupted: resuming reruns the jobs it left incomplete
    base = ["--configfile", *configfiles, "--config", f"results_dir={results}", "--rerun-incomplete"]
    # [I] One thread per job, and epoch 2's chain first (session 12's timed run): the rules that claim
    # both cores ran one at a time and used 1.1-1.6 of them (COLMAP's mapping, the renderer and the
    # georeferencing are partly serial; one dense tile ran 1.6x faster on 2 threads than on 1), and
    # Snakemake started epoch 2's twin -> render -> SfM -> georeferencing chain only after epoch 1's
    # dense tiles. With one thread each, two jobs share the two cores, and the longest chain starts first.
    if args.mtime_only:
        base += ["--rerun-triggers", "mtime"]
    base += ["--set-threads", *(f"{r}=1" for r in ONE_THREAD_RULES),
             "--prioritize", str(results / site / "dense" / "epoch2" / "dsm.tif")]

    rows = []
    if args.dry_run:
        snakemake(["-n", "--cores", str(args.cores), *base], site_dir / "benchmark_dryrun.log", env)
        print((site_dir / "benchmark_dryrun.log").read_text()[-3000:])
        return 0
    tile_rules, merge_rules = scaling_targets(args.scaling_rules)
    retabulate = args.collect_only or args.scaling_only
    if not retabulate:
        log_path = run_log(site_dir)
        earlier = [w for w in (wall_from_log(p) for p in sorted(site_dir.glob("benchmark_run*.log"))) if w is not None]
        wall = snakemake(["--cores", str(args.cores), *base], log_path, env)
        if earlier:  # a resumed run: what the earlier, interrupted runs of the same results took counts too
            rows.append(("run", f"this run's wall ({log_path.name}, --cores {args.cores})", wall, "s", None, None))
            rows.append(("run", f"total wall (Snakemake, --cores {args.cores}, {len(earlier) + 1} runs: the logs' spans + this run)",
                         sum(earlier) + wall, "s", None, "<= 10800 (3 h)"))
        else:
            rows.append(("run", "total wall (Snakemake, --cores %d)" % args.cores, wall, "s", None, "<= 10800 (3 h)"))
    if retabulate:
        kept = timed_rows(site_dir / "benchmark.csv")
        rows.extend(r for r in kept if not (args.scaling_only and r[0] == "scaling"))  # new reruns replace old ones
    costs = rule_costs(site_dir)  # before the reruns below overwrite the tile jobs' benchmark files
    if (not args.collect_only) and not args.no_scaling:
        walls = {}
        for k in (1, 2):
            walls[k] = snakemake(["--cores", str(k), "--forcerun", *tile_rules, "--until", *merge_rules, *base],
                                 site_dir / f"benchmark_tiled_{k}core.log", env)
            rows.append(("scaling", scaling_label(tile_rules, k), walls[k], "s", None, None))
        rows.append(("scaling", "tiled stages speed-up 1 -> 2 cores", walls[1] / walls[2], "x", None, None))
    if retabulate:
        if not any(r[0] == "run" for r in rows):  # the wrapper did not time it (stopped, or resumed by hand): the logs
            logs = sorted(site_dir.glob("benchmark_run*.log"))
            spans = [w for w in (wall_from_log(p) for p in logs) if w is not None]
            if spans:
                rows.append(("run", f"total wall (Snakemake logs: {' + '.join(p.name for p in logs)}, --cores {args.cores})",
                             sum(spans), "s", None, "<= 10800 (3 h)"))
    for r in costs.itertuples(index=False):
        rows.append(("rule", f"{r.job} wall", r.wall_s, "s", None, None))
        rows.append(("rule", f"{r.job} CPU", r.cpu_s, "s", None, None))
        rows.append(("rule", f"{r.job} peak memory", r.max_rss_mb, "MB", None, "<= 8000"))
    for r in stage_costs(costs).itertuples(index=False):
        rows.append(("stage", f"{r.stage}: {r.jobs} jobs, summed wall", r.wall_s, "s", None, None))
        rows.append(("stage", f"{r.stage}: summed CPU", r.cpu_s, "s", None, None))
        rows.append(("stage", f"{r.stage}: largest peak memory", r.max_rss_mb, "MB", None, "<= 8000"))
    if len(costs):
        rows.append(("run", "largest peak memory of any job", costs["max_rss_mb"].max(), "MB", None, "<= 8000"))
        rows.append(("run", "sum of job wall times", costs["wall_s"].sum(), "s", None, None))
        rows.append(("run", "jobs with a benchmark file", len(costs), "", None, None))
    peaks = log_peaks(site_dir)
    for r in peaks.itertuples(index=False):
        rows.append(("rule", f"{r.job} peak memory (high-water mark, log)", r.peak_mb, "MB", None, "<= 8000"))
    if len(peaks):
        top = peaks.iloc[0]
        rows.append(("run", f"largest peak memory of any job (high-water mark from the logs: {top['job']})",
                     top["peak_mb"], "MB", None, "<= 8000"))
        rows.append(("run", "jobs whose log states its peak memory", len(peaks), "", None, None))
    acc = accuracies(site_dir)
    keep_below_target(site_dir, acc)
    for name, value in acc.items():
        unit, paper, target = PAPER.get(name, ("", None, None))
        rows.append(("accuracy", name, value, unit, paper, target))
    df = pd.DataFrame(rows, columns=["kind", "item", "value", "unit", "paper", "target"])
    df.insert(0, "extent", label)
    write_table(df, site_dir / "benchmark.csv")
    print(f"{label}: {len(df)} rows -> {site_dir / 'benchmark.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
