"""The whole chain on an ensemble of twins (issue 15): one summary row per twin, mean and worst.

Members: ``default`` (config/sites/kamech_twin.yaml alone) and every
``config/sites/ensemble/*.yaml`` (small override files merged on top of the base site file
by Snakemake: ``--configfile <base> <member> <override>``). For each member the script runs
Snakemake for the products it scores (flight summary, georeferencing against the flight
truth, dense DSM, checkpoint validation, gully map and validation with the digitised heads,
kite-scale bare soil), then maps the gullies once more with automatic heads
(``gully.heads: automatic``, library call on the member's photogrammetric DSM) and scores
both head sources with the same protocol (:func:`kitegully.evaluate.gully_run.score_gully_run`).

Writes ``<out>/summary.csv`` (one row per twin) and ``<out>/summary.md`` (rows, mean, worst).

    .venv/bin/python benchmarks/twin_ensemble.py [--cores 2] [--members default,ens1,...]
    .venv/bin/python benchmarks/twin_ensemble.py --dry-run          # snakemake -n per member
    .venv/bin/python benchmarks/twin_ensemble.py --tiny             # one cheap member: the tiny twin
    .venv/bin/python benchmarks/twin_ensemble.py --collect-only     # score existing results
    .venv/bin/python benchmarks/twin_ensemble.py --collect-only --regully --results /path/to/results \
        --out results/ensemble_regully    # map the existing members' DSMs again with the current gully code

The full ensemble (6 Kamech-sized chains) takes about 6 x 10 min on 2 idle cores.
"""

from __future__ import annotations

import argparse
import copy
import json
import logging
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.evaluate.gully_run import score_gully_run  # noqa: E402
from kitegully.evaluate.dem import read_checkpoints  # noqa: E402
from kitegully.gully.heads import HeadDetectionParams  # noqa: E402
from kitegully.gully.relief import dsm_noise_at_checkpoints  # noqa: E402
from kitegully.gully.params import GullyParams  # noqa: E402
from kitegully.gully.pipeline import map_gullies  # noqa: E402
from kitegully.io.raster import read_raster  # noqa: E402
from kitegully.io.vectors import read_vector  # noqa: E402

log = logging.getLogger("twin_ensemble")

BASE = REPO / "config/sites/kamech_twin.yaml"
TINY = REPO / "config/sites/tiny_twin.yaml"
ENSEMBLE_DIR = REPO / "config/sites/ensemble"
TOLERANCES = (2.0, 5.0, 15.0)

#: Products scored per member (relative to results/<site>/); the OBIA one only when enabled.
TARGETS = {
    "flight": "flight/flight_summary.csv",
    "georef": "georef/twin_evaluation.json",
    "dense": "dense/dense_summary.csv",
    "validate": "validate/checkpoint_summary.csv",
    "gully_validation": "gully/network_validation_tolerances.csv",
    "gully_area": "gully/gully_area_scores.csv",
    "obia": "obia/kite/accuracy.csv",
}

#: With ``--change`` (issue 17): the epoch-2 chain and the change stage of the same member.
CHANGE_TARGET = "change/evaluation_summary.csv"

#: Rows of the change stage's evaluation summary collected per member (column name, quantity).
CHANGE_ROWS = {
    "change_net_error_pct": "site_net_error_pct",
    "change_truth_within_1sd": "target: truth within stated 1 sd",
    "change_false_detection_pct": "false detection rate on unchanged cells, 95 %",
    "headcut_n_retreated": "headcut |error| n, heads that retreated, lip, stated",
    "headcut_median_error_retreated_m": "headcut |error| median, heads that retreated, lip, stated",
    "headcut_p90_error_retreated_m": "headcut |error| p90, heads that retreated, lip, stated",
    "headcut_n_stable": "headcut |error| n, stable heads, lip, stated",
    "headcut_median_error_stable_m": "headcut |error| median, stable heads, lip, stated",
    "headcut_true_surfaces_median_error_retreated_m": "headcut |error| median, heads that retreated, lip, method on the true surfaces",
    "moritani_mae_m": "moritani MAE",
    "moritani_b": "moritani b",
}

#: Columns where larger is worse (the "worst" row takes the maximum); others take the minimum.
WORSE_IF_LARGER = ("camera_rmse_m", "camera_max_m", "checkpoint_abs_mean_m", "checkpoint_sd_m", "gsd_median_m",
                   "false_positive", "false_negative", "head_median_distance_m", "chain_wall_s", "time_s", "mapping_s",
                   "error", "false_detection", "moritani_mae")
NOT_SCORED = ("member", "seed", "base", "description", "checkpoint_mean_m", "change_net_error_pct", "headcut_n_retreated",
              "headcut_n_stable")


def deep_merge(a: dict, b: dict) -> dict:
    """``b`` merged into a copy of ``a``, dicts recursively (as Snakemake merges config files)."""
    out = copy.deepcopy(a)
    for k, v in b.items():
        out[k] = deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


def members(names: list[str] | None, base: Path, member_dir: Path = ENSEMBLE_DIR) -> list[tuple[str, list[Path]]]:
    """(name, override files) per member; ``default`` has none and belongs to the ensemble's folder only
    (``config/sites/holdout``: the held-out twins alone)."""
    found = {"default": []} if member_dir == ENSEMBLE_DIR else {}
    by_number = lambda p: (p.stem.rstrip("0123456789"), int(p.stem[len(p.stem.rstrip("0123456789")):] or 0))  # noqa: E731
    found.update({p.stem: [p] for p in sorted(member_dir.glob("*.yaml"), key=by_number)})  # h2 before h10
    if names:
        unknown = [n for n in names if n not in found]
        if unknown:
            raise SystemExit(f"unknown ensemble member(s) {unknown}; known: {sorted(found)}")
        return [(n, found[n]) for n in names]
    return list(found.items())


def member_config(base: Path, files: list[Path], name: str, out: Path) -> tuple[dict, list[Path]]:
    """Merged config and the list of config files for Snakemake (base, member, name override)."""
    cfg = yaml.safe_load(base.read_text())
    for f in files:
        cfg = deep_merge(cfg, yaml.safe_load(f.read_text()))
    site = cfg["site"]["name"] if name == "default" else name
    if base == TINY and name != "default":
        site = f"tiny_{name}"
    # the ensemble scores the photogrammetric DSM (never the truth-plus-noise stand-in)
    override = {"site": {"name": site}, "gully": {"dem": "dense"}}
    if cfg.get("obia", {}).get("kite_scale", {}).get("enabled") is False:
        log.warning("%s: obia.kite_scale disabled; no bare-soil accuracy", name)
    cfg = deep_merge(cfg, override)
    out.mkdir(parents=True, exist_ok=True)
    ov = out / f"{name}_override.yaml"
    ov.write_text(yaml.safe_dump(override))
    return cfg, [base, *files, ov]


def targets_for(cfg: dict, results: Path, change: bool = False) -> dict[str, Path]:
    """Scored products, relative to the repository (Snakemake matches rule outputs as written);
    ``change``: also the change stage's evaluation (epoch 2 through the whole chain)."""
    site = results / cfg["site"]["name"]
    t = {k: site / v for k, v in TARGETS.items()}
    if change:
        t["change"] = site / CHANGE_TARGET
    if not cfg.get("obia", {}).get("kite_scale", {}).get("enabled", False):
        t.pop("obia")
    return t


def run_snakemake(configfiles: list[Path], targets: list[Path], cores: int, dry_run: bool, log_path: Path,
                  extra_args: str = "") -> float:
    """Run (or dry-run) Snakemake for ``targets``; returns wall seconds. Raises on failure.

    ``extra_args``: more Snakemake options, shell-quoted (e.g. ``--rerun-triggers mtime
    --forcerun gully_map``: remake the gully rules after a change of library code, not the chain
    whose recorded parameters differ).
    """
    # targets first: --configfile takes every argument after it
    cmd = [sys.executable, "-m", "snakemake", *map(str, targets), "--cores", str(cores),
           *(["-n"] if dry_run else []), *shlex.split(extra_args),
           "--configfile", *map(str, configfiles)]
    env = dict(os.environ, PYTHONPATH=str(REPO / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t0 = time.perf_counter()
    with open(log_path, "w") as fh:
        proc = subprocess.run(cmd, cwd=REPO, env=env, stdout=fh, stderr=subprocess.STDOUT)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"snakemake failed (rc {proc.returncode}); see {log_path}: {' '.join(cmd)}")
    return wall


def _quantity(path: Path, key: str, col: str = "quantity", val: str = "value") -> float:
    df = pd.read_csv(path)
    s = df.loc[df[col] == key, val]
    return float(s.iloc[0]) if len(s) else float("nan")


def collect(cfg: dict, t: dict[str, Path], results: Path, regully: bool = False,
            sources: tuple[str, ...] = ("digitised", "automatic", "both")) -> dict:
    """Every summary number of one member from its result files (NaN where a file is missing)."""
    row: dict = {}
    nan = float("nan")
    row["gsd_median_m"] = _quantity(t["flight"], "gsd_median") if t["flight"].exists() else nan
    if t["georef"].exists():
        g = json.loads(t["georef"].read_text())
        row["camera_rmse_m"] = g.get("camera_rmse_m", nan)
        row["camera_max_m"] = g.get("camera_max_error_m", nan)
    if t["validate"].exists():
        row["checkpoint_mean_m"] = _quantity(t["validate"], "mean", "statistic", "value_m")
        row["checkpoint_abs_mean_m"] = abs(row["checkpoint_mean_m"])
        row["checkpoint_sd_m"] = _quantity(t["validate"], "sd", "statistic", "value_m")
    row["dsm_coverage_pct"] = _quantity(t["dense"], "coverage_of_seen_pct") if t["dense"].exists() else nan
    if "obia" in t and t["obia"].exists():
        row["kite_bare_soil_oa_pct"] = float(pd.read_csv(t["obia"])["overall_accuracy"].iloc[0])
    if "change" in t and t["change"].exists():
        df = pd.read_csv(t["change"])
        for col, key in CHANGE_ROWS.items():
            s = df.loc[df["quantity"] == key, "value"]
            row[col] = float(s.iloc[0]) if len(s) else nan
        row["change_abs_net_error_pct"] = abs(row["change_net_error_pct"])
    site = results / cfg["site"]["name"]
    row.update(score_heads_both(cfg, site, regully, sources))
    return row


def score_heads_both(cfg: dict, site: Path, regully: bool = False,
                     sources: tuple[str, ...] = ("digitised", "automatic", "both")) -> dict:
    """Gully scores with the digitised heads (the rule's map) and with automatic heads (library run).

    With ``gully.heads`` other than ``digitised`` in the member's config, every head source is
    mapped by the library (:func:`regully_member`), as with ``regully``.

    ``regully``: map the member's dense DSM again with the current gully code and settings for
    all three head sources (``digitised``, ``automatic``, ``both``; columns ``dig_``, ``auto_``,
    ``both_``) instead of reading the rule's digitised map: existing members are rescored
    without rerunning the photogrammetric chain.
    """
    g = cfg["gully"]
    crs = cfg["site"]["crs"]
    dsm_path = site / "dense/dsm.tif"
    if not dsm_path.exists():
        return {}
    dem, grid = read_raster(dsm_path)
    dem = np.asarray(dem, dtype=np.float32)
    twin = site / "twin"
    ref = read_vector(twin / "observed/field_network.gpkg", crs=crs)
    polys = read_vector(twin / "truth/gully_polygons.gpkg", crs=crs)
    th = read_vector(twin / "truth/gully_heads.gpkg", crs=crs)
    true_xy = np.column_stack([th.geometry.x, th.geometry.y])
    valid = np.isfinite(dem)
    out: dict = {}
    if regully:
        return regully_member(g, twin, dem, grid, ref, polys, true_xy, crs, sources)
    if g["heads"] != "digitised":
        # the rule mapped with gully.heads: both (the Kamech default) or automatic: all three sources are
        # mapped by the library on the same DSM with the same settings (deterministic: that source's
        # columns are the rule's map), since the rule's products hold no map of the digitised heads alone
        return regully_member(g, twin, dem, grid, ref, polys, true_xy, crs)
    # digitised: the pipeline's own products
    gm = site / "gully/gully_map.tif"
    if gm.exists():
        gully, _ = read_raster(gm)
        ext = read_vector(site / "gully/gully_network_mapped.gpkg", crs=crs)
        dh = read_vector(twin / "observed/gully_heads.gpkg", crs=crs)
        s = score_gully_run(gully == 1, ext, valid, grid, ref, polys, TOLERANCES, g["validation"]["reference_join_m"],
                            np.column_stack([dh.geometry.x, dh.geometry.y]), true_xy)
        out.update({f"dig_{k}": v for k, v in s.items()})
    # automatic: same DSM, heads from the data alone
    t0 = time.perf_counter()
    sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(twin / "observed/checkpoints.csv"))
    out["dsm_sigma_z_at_checkpoints_m"] = sz
    params = GullyParams.from_config(g)
    ortho = None
    if params.crowns.enabled:  # gully.crowns: the member's orthophoto on the DSM grid
        from kitegully.gully.inputs import read_orthophoto_on_grid

        ortho = read_orthophoto_on_grid(site / "dense/orthophoto.tif", grid)
    res = map_gullies(dem, grid, np.zeros(0), np.zeros(0), params, workers=1,
                      auto_heads=HeadDetectionParams.from_config(g["automatic_heads"], sz), ortho=ortho)
    xs, ys = grid.cell_centres()
    r, c = np.divmod(res.auto_heads, grid.width)
    s = score_gully_run(res.gully, res.extracted_lines, valid, grid, ref, polys, TOLERANCES,
                        g["validation"]["reference_join_m"], np.column_stack([xs[c], ys[r]]), true_xy)
    out.update({f"auto_{k}": v for k, v in s.items()})
    out["auto_mapping_s"] = time.perf_counter() - t0
    return out


def regully_member(g: dict, twin: Path, dem: np.ndarray, grid, ref, polys, true_xy: np.ndarray, crs: str,
                   sources: tuple[str, ...] = ("digitised", "automatic", "both")) -> dict:
    """Scores of ``map_gullies`` with the head ``sources`` (digitised, automatic, both) on one member's DSM."""
    from kitegully.gully.inputs import read_heads

    valid = np.isfinite(dem)
    hx, hy = read_heads(str(twin / "observed/gully_heads.gpkg"), crs)
    sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(twin / "observed/checkpoints.csv"))
    out: dict = {"dsm_sigma_z_at_checkpoints_m": sz}
    params = GullyParams.from_config(g)
    ortho = None
    if params.crowns.enabled:  # gully.crowns: the member's orthophoto on the DSM grid
        from kitegully.gully.inputs import read_orthophoto_on_grid

        ortho = read_orthophoto_on_grid(twin.parent / "dense/orthophoto.tif", grid)
    xs, ys = grid.cell_centres()
    for src, key in (("digitised", "dig"), ("automatic", "auto"), ("both", "both")):
        if src not in sources:
            continue
        t0 = time.perf_counter()
        ip = HeadDetectionParams.from_config(g["automatic_heads"], sz)
        auto = ip if src != "digitised" else None
        x, y = (hx, hy) if src != "automatic" else (np.zeros(0), np.zeros(0))
        res = map_gullies(dem, grid, x, y, params, workers=1, auto_heads=auto, incision=ip, ortho=ortho)
        if res.bridged is not None:
            out[f"{key}_bridged_m"] = float(res.bridged.sum()) * grid.cell
        r, c = np.divmod(res.auto_heads, grid.width)
        used = np.concatenate([np.column_stack([x, y]), np.column_stack([xs[c], ys[r]])])
        s = score_gully_run(res.gully, res.extracted_lines, valid, grid, ref, polys, TOLERANCES,
                            g["validation"]["reference_join_m"], used, true_xy)
        out.update({f"{key}_{k}": v for k, v in s.items()})
        out[f"{key}_n_heads"] = len(used)
        out[f"{key}_mapping_s"] = time.perf_counter() - t0
        log.info("regully %s: good fit 5 m %.1f %%, FP %.1f %%, IoU %.3f, %d heads", src, s["good_fit_5m_pct"],
                 s["false_positive_5m_pct"], s.get("iou", float("nan")), len(used))
    return out


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """Rows plus ``mean`` and ``worst`` rows (worst = max where larger is worse, else min)."""
    num = [c for c in df.columns if c not in NOT_SCORED and pd.api.types.is_numeric_dtype(df[c])]
    mean = {c: df[c].mean() for c in num}
    worst = {c: (df[c].max() if any(w in c for w in WORSE_IF_LARGER) else df[c].min()) for c in num}
    for signed in ("checkpoint_mean_m", "change_net_error_pct"):  # signed: worst = largest |bias|
        if signed in df.columns and df[signed].notna().any():
            mean[signed] = df[signed].mean()
            worst[signed] = df[signed].loc[df[signed].abs().idxmax()]
    mean["member"], worst["member"] = "mean", "worst"
    return pd.concat([df, pd.DataFrame([mean, worst])], ignore_index=True)


MD_COLUMNS = [
    ("member", "twin"), ("gsd_median_m", "GSD (m)"), ("camera_rmse_m", "camera RMSE (m)"), ("camera_max_m", "camera max (m)"),
    ("checkpoint_mean_m", "checkpoint mean (m)"), ("checkpoint_sd_m", "checkpoint SD (m)"), ("dsm_coverage_pct", "DSM coverage (%)"),
    *[(f"{src}_{cat}_{t:g}m_pct", f"{lab} {short} {t:g} m (%)")
      for src, lab in (("dig", "digitised"), ("auto", "automatic"), ("both", "both"))
      for t in TOLERANCES for cat, short in (("good_fit", "good fit"), ("false_positive", "FP"), ("false_negative", "FN"))],
    ("dig_iou", "gully IoU (digitised)"), ("auto_iou", "gully IoU (automatic)"), ("both_iou", "gully IoU (both)"),
    ("auto_n_heads", "automatic heads"),
    ("auto_head_precision", "auto head precision"), ("auto_head_recall", "auto head recall"),
    ("kite_bare_soil_oa_pct", "kite bare-soil OA (%)"),
    ("change_net_error_pct", "change: net error (%)"), ("change_abs_net_error_pct", "change: |net error| (%)"),
    ("change_truth_within_1sd", "change: truth within 1 SD"),
    ("change_false_detection_pct", "change: false detections (%)"),
    ("headcut_median_error_retreated_m", "headcut |error| median, retreated (m)"), ("headcut_n_retreated", "retreated heads"),
    ("headcut_median_error_stable_m", "headcut |error| median, stable (m)"),
    ("headcut_true_surfaces_median_error_retreated_m", "headcut on true surfaces, retreated (m)"),
    ("moritani_mae_m", "Moritani MAE (m)"), ("moritani_b", "Moritani b"),
]


def write_outputs(df: pd.DataFrame, out: Path, note: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    full = summarise(df)
    full.to_csv(out / "summary.csv", index=False)
    cols = [(c, h) for c, h in MD_COLUMNS if c in full.columns]
    lines = [f"# Twin ensemble summary\n\n{note}\n", "| " + " | ".join(h for _, h in cols) + " |",
             "|" + "---|" * len(cols)]
    for _, r in full.iterrows():
        cells = []
        for c, _ in cols:
            v = r[c]
            cells.append(f"{v:.3g}" if isinstance(v, (float, np.floating)) and c.endswith("_m") else
                         f"{v:.1f}" if isinstance(v, (float, np.floating)) and "pct" in c else
                         f"{v:.2f}" if isinstance(v, (float, np.floating)) else str(v))
        bold = r["member"] in ("mean", "worst")
        lines.append("| " + " | ".join(f"**{x}**" if bold else x for x in cells) + " |")
    lines.append("\nPaper (Feurer et al. 2018, Table 4 / sect. 3): good fit 74 %, FP 8 %, FN 26 % (tolerance not stated); "
                 "DEM error mean +0.06 m, SD 0.22 m.")
    (out / "summary.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--members", default=None, help="comma-separated (default: default + every ensemble file)")
    ap.add_argument("--tiny", action="store_true", help="base = the tiny twin, member 'default' only unless --members")
    ap.add_argument("--dry-run", action="store_true", help="snakemake -n per member; nothing is scored")
    ap.add_argument("--collect-only", action="store_true", help="score existing results without running Snakemake")
    ap.add_argument("--regully", action="store_true",
                    help="with --collect-only: map each member's existing dense DSM again with the current gully code "
                         "(digitised, automatic and both heads) instead of reading the rule's gully map")
    ap.add_argument("--sources", default="digitised,automatic,both",
                    help="with --regully: comma-separated head sources to map (digitised, automatic, both)")
    ap.add_argument("--set", action="append", default=[],
                    help="with --regully: gully key=value (yaml value) overrides of every member's config")
    ap.add_argument("--snakemake-args", default="",
                    help="more snakemake options, one quoted string, e.g. '--rerun-triggers mtime --forcerun gully_map' "
                         "(remake the gully rules after a change of library code without remaking the chain)")
    ap.add_argument("--member-dir", default=str(ENSEMBLE_DIR.relative_to(REPO)),
                    help="folder of member override files (config/sites/holdout: the held-out twins, never used to "
                         "write or choose a method; without the default member)")
    ap.add_argument("--change", action="store_true",
                    help="also run and score epoch 2 and the change stage (issue 17: net volume, false detections, "
                         "headcut retreat per member)")
    ap.add_argument("--results", default="results")
    ap.add_argument("--out", default=None, help="default results/ensemble (results/ensemble_tiny with --tiny)")
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if a.regully and not a.collect_only:
        raise SystemExit("--regully rescores existing results: use it with --collect-only")
    base = TINY if a.tiny else BASE
    names = a.members.split(",") if a.members else (["default"] if a.tiny else None)
    results = Path(a.results)  # relative to REPO, like the rule outputs
    out = REPO / (a.out or ("results/ensemble_tiny" if a.tiny else "results/ensemble"))
    rows = []
    chosen = members(names, base, REPO / a.member_dir)
    for name, files in chosen:
        cfg, cfiles = member_config(base, files, name, out / "configs")
        t = targets_for(cfg, results, a.change)
        wall = float("nan")
        if not a.collect_only:
            log.info("%s: snakemake %s (%s)", name, "dry-run" if a.dry_run else "run", cfg["site"]["name"])
            wall = run_snakemake(cfiles, list(t.values()), a.cores, a.dry_run, out / "configs" / f"{name}_snakemake.log",
                                 a.snakemake_args)
            log.info("%s: snakemake done in %.0f s", name, wall)
        if a.dry_run:
            continue
        row = {"member": name, "site": cfg["site"]["name"], "seed": cfg["seed"], "base": base.name, "chain_wall_s": wall}
        for kv in a.set:
            k, v = kv.split("=", 1)
            cfg["gully"][k] = yaml.safe_load(v)
        row.update(collect(cfg, {k: REPO / v for k, v in t.items()}, REPO / results, a.regully,
                           tuple(a.sources.split(","))))
        rows.append(row)
        log.info("%s: %s", name, {k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()})
    if a.dry_run:
        log.info("dry run done for %d member(s)", len(chosen))
        return
    note = (f"Base site file {base.relative_to(REPO)}; members {', '.join(r['member'] for r in rows)}. "
            "Gully scores: paper protocol (reference lines fed by heads on the DEM), tolerances 2/5/15 m, "
            + ("all three head sources mapped again on each member's existing dense DSM with the current gully code "
               "(--regully): digitised = the twin's digitised heads, automatic = gully.heads: automatic, both = digitised "
               "plus automatic heads beyond the snapping radius." if a.regully else
               "digitised = the rule's map from the twin's digitised heads, automatic = gully.heads: automatic on the same DSM."))
    write_outputs(pd.DataFrame(rows), out, note)
    log.info("wrote %s and %s", out / "summary.csv", out / "summary.md")


if __name__ == "__main__":
    main()
