"""Benchmark: our seeded region growing vs SAGA GIS and scikit-image segmenters.

On one synthetic close-range scene (config ``obia.scenes``, first scene) it times

* kitegully: variance-minimum seeds + numba seeded region growing (R, G, B, slope);
* SAGA GIS ``imagery_segmentation`` tool 2 (Seed Generation) + tool 3 (Seeded Region
  Growing) on the same four features; Debian's ``saga`` is installed with
  ``apt-get install -y saga`` when ``saga_cmd`` is missing (skipped with a message if
  that is impossible);
* scikit-image SLIC and Felzenszwalb on the RGB orthophoto,

and compares the segmentations: number of segments, adapted Rand error and variation of
information against ours, and the overall accuracy the ExG classification reaches
when it uses each segmentation (segment mean ExG against the same valley threshold).

    .venv/bin/python benchmarks/obia_benchmark.py [--site config/sites/kamech_twin.yaml]
        [--scene 0] [--no-install] [--out results/benchmarks/obia]

Writes ``obia_benchmark.csv`` / ``.md`` in ``--out``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.config import load_yaml  # noqa: E402
from kitegully.io.raster import read_raster, write_raster  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402
from kitegully.obia.accuracy import accuracies, confusion_matrix  # noqa: E402
from kitegully.obia.classify import classify_segments, segment_means  # noqa: E402
from kitegully.obia.features import normalise_features  # noqa: E402
from kitegully.obia.scene import ObiaParams, classify_scene, marker_mask  # noqa: E402
from kitegully.obia.seeds import generate_seeds  # noqa: E402
from kitegully.obia.slope import wood_slope  # noqa: E402
from kitegully.obia.srg import seeded_region_growing  # noqa: E402
from kitegully.twin.closerange import generate_scene, scene_names, scene_origin  # noqa: E402


def ensure_saga(install: bool) -> str | None:
    """Path of saga_cmd, installing Debian's saga package if allowed; None if unavailable."""
    exe = shutil.which("saga_cmd")
    if exe or not install:
        return exe
    if shutil.which("apt-get") is None:
        print("SAGA skipped: saga_cmd not found and apt-get is not available")
        return None
    sudo = [] if os.geteuid() == 0 else (["sudo", "-n"] if shutil.which("sudo") else None)
    if sudo is None:
        print("SAGA skipped: saga_cmd not found and not root to run apt-get")
        return None
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (sudo + ["apt-get", "update"], sudo + ["apt-get", "install", "-y", "saga"]):
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if proc.returncode != 0:
            print(f"SAGA skipped: {' '.join(cmd)} failed: {proc.stderr.strip()[-300:]}")
            return None
    return shutil.which("saga_cmd")


def run_saga(exe: str, feats: np.ndarray, grid, bandwidth: int, workdir: Path) -> tuple[np.ndarray, float] | None:
    """SAGA Seed Generation (tool 2) + Seeded Region Growing (tool 3); (labels, seconds)."""
    paths = []
    for k in range(feats.shape[-1]):
        p = workdir / f"feature_{k}.tif"
        write_raster(p, feats[..., k].astype(np.float32), grid)
        paths.append(str(p))
    seeds = workdir / "seeds.sdat"
    segments = workdir / "segments.sdat"
    t0 = time.perf_counter()
    steps = [
        [exe, "imagery_segmentation", "2", "-FEATURES", ";".join(paths), "-VARIANCE", str(workdir / "variance.sdat"),
         "-SEED_GRID", str(seeds), "-SEED_TYPE", "0", "-METHOD", "0", "-BAND_WIDTH", str(bandwidth), "-NORMALIZE", "0"],
        [exe, "imagery_segmentation", "3", "-SEEDS", str(seeds), "-FEATURES", ";".join(paths), "-SEGMENTS", str(segments),
         "-SIMILARITY", str(workdir / "similarity.sdat"), "-TABLE", str(workdir / "seeds_table.txt"), "-NORMALIZE", "0", "-NEIGHBOUR", "0", "-METHOD", "0", "-SIG_1", "1", "-SIG_2", "1", "-THRESHOLD", "0"],
    ]
    for cmd in steps:
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            print(f"SAGA failed ({' '.join(cmd[:3])}): {proc.stdout[-1500:]} {proc.stderr[-1500:]}")
            return None
    seconds = time.perf_counter() - t0
    labels, _ = read_raster(segments)
    labels = np.nan_to_num(labels, nan=0).astype(np.int64)
    return labels, seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default=str(REPO / "config" / "sites" / "kamech_twin.yaml"))
    ap.add_argument("--scene", type=int, default=0, help="index of the scene in obia.scenes.list")
    ap.add_argument("--no-install", action="store_true", help="do not apt-get install saga")
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "obia"))
    args = ap.parse_args()

    from skimage.metrics import adapted_rand_error, variation_of_information
    from skimage.segmentation import felzenszwalb, slic

    site = load_yaml(args.site)
    cfg = site["obia"]
    params = ObiaParams.from_config(cfg)
    sc = cfg["scenes"]
    name = scene_names(len(sc["list"]))[args.scene]
    scene = generate_scene(name, sc, sc["list"][args.scene], site["seed"], site["site"]["crs"], scene_origin(args.scene, sc))
    valid = ~marker_mask(scene.dem.shape, scene.grid, scene.markers, cfg["classification"]["marker_mask_factor"])
    ref = classify_scene(scene.rgb, scene.dem, scene.grid.cell, params, valid=valid, source=name)  # warm-up (numba)
    rgb = scene.rgb.astype(np.float32)
    threshold = ref.threshold.valley
    print(f"{name}: {scene.rgb.shape[1]} x {scene.rgb.shape[2]} cells, valley threshold {threshold}")

    def score(labels: np.ndarray) -> float:
        labels = np.where(valid, labels, 0)
        n = int(labels.max())
        means = segment_means(ref.exg_blur, labels, n)
        cls = classify_segments(means, labels, threshold)
        return 100 * accuracies(confusion_matrix(cls, scene.truth_eroded, valid=valid & (labels > 0)))["overall"]

    rows = []

    def add(method: str, labels: np.ndarray, seconds: float) -> None:
        lab = np.where(valid, labels, 0).astype(np.int64)
        ours = ref.segments.astype(np.int64)
        are = adapted_rand_error(ours + 1, lab + 1)[0]
        vi = sum(variation_of_information(ours, lab))
        rows.append({"method": method, "time_s": seconds, "segments": int(len(np.unique(lab[lab > 0]))),
                     "adapted_rand_error_vs_ours": are, "variation_of_information_vs_ours": vi,
                     "classification_oa_pct": score(lab)})
        print(rows[-1])

    t0 = time.perf_counter()
    slope = wood_slope(scene.dem, scene.grid.cell, params.slope_window_cells)
    feats = normalise_features([rgb[0], rgb[1], rgb[2], slope], valid)
    seeds = generate_seeds(feats, valid, params.seed_bandwidth_cells)
    labels, _ = seeded_region_growing(feats, seeds, valid, params.position_weight)
    add("kitegully SRG (seeds + numba growing)", labels, time.perf_counter() - t0)

    exe = ensure_saga(not args.no_install)
    if exe:
        with tempfile.TemporaryDirectory() as tmp:
            got = run_saga(exe, feats, scene.grid, params.seed_bandwidth_cells, Path(tmp))
        if got is not None:
            add("SAGA imagery_segmentation 2 + 3", *got)
    else:
        print("SAGA GIS not available: comparison skipped")

    img = np.moveaxis(scene.rgb, 0, -1).astype(np.float64) / 255.0
    t0 = time.perf_counter()
    lab = slic(img, n_segments=int(seeds.max()), compactness=10.0, start_label=1, mask=valid)
    add("scikit-image SLIC", lab, time.perf_counter() - t0)
    t0 = time.perf_counter()
    lab = felzenszwalb(img, scale=100, sigma=0.5, min_size=50) + 1
    add("scikit-image Felzenszwalb", lab, time.perf_counter() - t0)

    out = Path(args.out)
    write_table(pd.DataFrame(rows), out / "obia_benchmark.csv", floatfmt=".3g")
    print((out / "obia_benchmark.md").read_text())


if __name__ == "__main__":
    main()
