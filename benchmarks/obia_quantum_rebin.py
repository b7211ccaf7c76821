#!/usr/bin/env python
"""Kite-scale bare-soil map with the lowest-mode re-binning limited to a minimum bin width (evaluation only).

The obia stage's threshold (:func:`kitegully.obia.threshold.find_bare_threshold`) re-bins the part of the
histogram below each valley into up to ``hist_bins`` bins over the range it occupies. On an 8-bit orthophoto
ExG = (2G − R − B)/(R + G + B) is quantised: one DN of G moves it by about 2 / (R + G + B), 0.004 for soil of DN
sum 500, and bins finer than that resolve the comb of quantised values as modes (session 41: a 600 × 400 m corner
of ``kamech_full`` split its ploughed soil there, OA 45.1 %). This script runs the stage's own
:func:`kitegully.obia.kite.bare_soil_map` twice on a finished site's ``dense/orthophoto.tif`` and ``dsm.tif``: as the
stage does, and with :func:`kitegully.obia.threshold.central_histogram` wrapped so that no re-binned bin is narrower
than ``--min-bin``; both maps are scored against the twin's land cover as the ``obia_kite_accuracy`` rule does.
Nothing under the site's results is written. Not the stage's rule: a library rule would take the quantum from the
orthophoto's data type and the brightness of the cells below the valley (docs/stages/07_obia.md).

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/obia_quantum_rebin.py --results results/ens4 \\
        --site config/sites/kamech_twin.yaml [--min-bin 0.004] [--tile-cells 2048]

About 1 min per 6 M-cell site on 2 cores.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

import kitegully.obia.threshold as threshold
from kitegully.io.raster import read_raster
from kitegully.obia.kite import bare_soil_map
from kitegully.obia.scene import ObiaParams
from kitegully.obia.stage import kite_accuracy

REPO = Path(__file__).resolve().parents[1]


def run(results: Path, site: Path, tile_cells: int, min_bin: float | None) -> dict:
    """One map (re-binning as the stage does when ``min_bin`` is None) and its scores."""
    cfg = yaml.safe_load(site.read_text())
    base = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    params = ObiaParams.from_config({**base.get("obia", {}), **cfg.get("obia", {})})
    original = threshold.central_histogram

    def limited(counts, edges, bins, tail_fraction=1e-3):
        lo, hi = threshold._central_bins(np.asarray(counts, np.int64), tail_fraction)
        span = (hi - lo + 1) * (edges[1] - edges[0])
        return original(counts, edges, min(bins, max(2, int(span / min_bin))), tail_fraction)

    if min_bin is not None:
        threshold.central_histogram = limited
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "bare_soil.tif"
            thr = bare_soil_map(results / "dense" / "orthophoto.tif", results / "dense" / "dsm.tif", out, params, tile_cells)
            bare, grid = read_raster(out)
    finally:
        threshold.central_histogram = original
    k = cfg["obia"]["kite_scale"]
    truth = results / "twin" / "truth"
    acc = kite_accuracy(bare, grid, str(truth / "landcover.tif"), pd.read_csv(truth / "landcover_classes.csv"),
                        str(truth / "landcover_classes.csv"), k["bare_landcover_classes"],
                        k["excluded_landcover_classes"], results.name).accuracy.set_index("class")
    return {"re-binning": "as the stage" if min_bin is None else f"bins >= {min_bin:g}", "valley": thr.valley,
            "valleys": thr.valleys, "OA_pct": acc.loc["bare", "overall_accuracy"],
            "bare_PA_pct": acc.loc["bare", "producers_accuracy"], "bare_UA_pct": acc.loc["bare", "users_accuracy"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, required=True, help="a finished twin site's results folder")
    ap.add_argument("--site", type=Path, required=True, help="the site's config file (its obia section)")
    ap.add_argument("--min-bin", type=float, default=0.004, help="narrowest re-binned bin (ExG)")
    ap.add_argument("--tile-cells", type=int, default=2048, help="as obia.kite_scale.tile_cells")
    a = ap.parse_args(argv)
    rows = [run(a.results, a.site, a.tile_cells, None), run(a.results, a.site, a.tile_cells, a.min_bin)]
    print(pd.DataFrame(rows).to_markdown(index=False, floatfmt=".4g"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
