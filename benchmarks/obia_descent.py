#!/usr/bin/env python
"""The kite bare-soil threshold with and without the descent's two resolution tests, on finished twin sites (evaluation only).

The obia stage's threshold (:func:`kitegully.obia.threshold.find_bare_threshold`) descends from the paper's two-peak
valley to the valley that bounds the lowest ExG mode, and keeps a further split only where (a) its bins are no
narrower than the index's one-DN step on the cells split (the quantisation floor) and (b) both sides are made of
unmixed cells (the mixed-cell test). This script makes the site's histogram once
(:func:`kitegully.obia.kite.site_histogram`, as the stage does) and scores four thresholds on each site's
``dense/orthophoto.tif`` against the twin's land cover, as the ``obia_kite_accuracy`` rule does:

- ``paper valley``: the first split only (Mayr et al. 2016);
- ``lowest mode, no tests``: the descent without (a) and (b);
- ``floor only``: with (a);
- ``stage``: with (a) and (b), the rule's own.

Each distinct valley is mapped once with :func:`kitegully.obia.kite.bare_soil_map`. Nothing under the sites' results
is written. ``--save-histogram DIR`` also writes each site's histogram (``<site>_histogram.npz``,
:meth:`kitegully.obia.threshold.IndexHistogram.save`), the form of the regression fixture in ``tests/obia/data/``.

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/obia_descent.py --results results/kamech_twin results/ens2 \\
        --site config/sites/kamech_twin.yaml [--tile-cells 2048] [--out results/benchmarks/obia_descent]

About 1 min per 6 M-cell site and threshold on 2 cores.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
from pathlib import Path

import pandas as pd
import yaml

from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.obia.kite import bare_soil_map, histogram_edges, site_histogram
from kitegully.obia.scene import ObiaParams
from kitegully.obia.stage import kite_accuracy
from kitegully.obia.threshold import IndexHistogram, ThresholdResult, find_bare_threshold

REPO = Path(__file__).resolve().parents[1]
log = logging.getLogger("obia_descent")


def thresholds(hist: IndexHistogram, params: ObiaParams) -> dict[str, ThresholdResult]:
    """The four thresholds of one site histogram, by variant name."""
    args = (hist.counts, histogram_edges(params), params.hist_bins, params.min_class_fraction, params.max_valley_ratio)
    steps = hist.step_sums if hist.quantised else None
    return {
        "paper valley": find_bare_threshold(*args, max_splits=0),  # the first split: the paper's two-peak valley
        "lowest mode, no tests": find_bare_threshold(*args),
        "floor only": find_bare_threshold(*args, fine_steps=steps),
        "stage": find_bare_threshold(*args, fine_steps=steps, fine_by_range=hist.by_range),
    }


def score_site(results: Path, params: ObiaParams, kite_cfg: dict, tile_cells: int, save_dir: Path | None) -> list[dict]:
    """Rows (variant, valleys, accuracies) for one finished site."""
    ortho, dsm = results / "dense" / "orthophoto.tif", results / "dense" / "dsm.tif"
    hist = site_histogram(ortho, dsm, params, tile_cells)
    if save_dir is not None:
        save_dir.mkdir(parents=True, exist_ok=True)
        hist.save(save_dir / f"{results.name}_histogram.npz")
    truth = results / "twin" / "truth"
    classes = pd.read_csv(truth / "landcover_classes.csv")
    scored: dict[float | None, pd.DataFrame] = {}
    rows = []
    for name, thr in thresholds(hist, params).items():
        if thr.valley not in scored:
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "bare_soil.tif"
                bare_soil_map(ortho, dsm, out, params, tile_cells, threshold=thr)
                bare, grid = read_raster(out)
            scored[thr.valley] = kite_accuracy(bare, grid, str(truth / "landcover.tif"), classes,
                                               str(truth / "landcover_classes.csv"), kite_cfg["bare_landcover_classes"],
                                               kite_cfg["excluded_landcover_classes"], results.name).accuracy.set_index("class")
            log.info("%s: %s mapped (valley %s)", results.name, name, thr.valley)
        acc = scored[thr.valley]
        valleys = thr.valleys or ([] if thr.valley is None else [thr.valley])
        rows.append({"site": results.name, "threshold": name, "valleys": ", ".join(f"{v:.4f}" for v in valleys),
                     "index_step": thr.index_step, "OA_pct": acc.loc["bare", "overall_accuracy"],
                     "bare_PA_pct": acc.loc["bare", "producers_accuracy"], "bare_UA_pct": acc.loc["bare", "users_accuracy"],
                     "stop_reason": thr.stop_reason or thr.reason})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, nargs="+", required=True, help="finished twin sites' results folders")
    ap.add_argument("--site", type=Path, required=True, help="the sites' config file (its obia section)")
    ap.add_argument("--tile-cells", type=int, default=2048, help="as obia.kite_scale.tile_cells")
    ap.add_argument("--out", type=Path, default=None, help="write <out>.csv and <out>.md")
    ap.add_argument("--save-histogram", type=Path, default=None, help="folder for each site's histogram")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    cfg = yaml.safe_load(a.site.read_text())
    base = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    params = ObiaParams.from_config({**base.get("obia", {}), **cfg.get("obia", {})})
    rows = [r for res in a.results for r in score_site(res, params, cfg["obia"]["kite_scale"], a.tile_cells, a.save_histogram)]
    table = pd.DataFrame(rows)
    print(table.to_markdown(index=False, floatfmt=".4g"))
    if a.out is not None:
        write_table(table, a.out.with_suffix(".csv"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
