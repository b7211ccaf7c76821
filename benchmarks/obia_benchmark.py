"""Benchmark: our seeded region growing vs SAGA GIS and scikit-image segmenters.

On one synthetic close-range scene (config ``obia.scenes``, first scene) it times

* kitegully: variance-minimum seeds + numba seeded region growing (R, G, B, slope);
* SAGA GIS ``imagery_segmentation`` tool 2 (Seed Generation) + tool 3 (Seeded Region
  Growing) on the same four features; Debian's ``saga`` is installed with
  ``apt-get install -y saga`` when ``saga_cmd`` is missing (skipped with a message if
  that is impossible);
* scikit-image SLIC and Felzenszwalb on the RGB orthophoto,

and compares the segmentations: number of seeds and segments, adjusted Rand index,
area-weighted best-match IoU and variation of information against ours, and the overall
accuracy the ExG classification reaches when it uses each segmentation (segment mean
ExG against the same valley threshold).  Every SAGA input is first imported into a
native SAGA grid (``io_gdal 0``) so tools 2 and 3 see one grid system; tool 3 also runs
from our seeds to separate the seeding from the growing.  SAGA times include process
start and grid I/O; the GeoTIFF import is reported but not counted.

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
import rasterio

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.config import load_yaml  # noqa: E402
from kitegully.io.raster import write_raster  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402
from kitegully.obia.accuracy import accuracies, confusion_matrix  # noqa: E402
from kitegully.obia.classify import classify_segments, segment_means  # noqa: E402
from kitegully.obia.scene import ObiaParams, classify_scene, marker_mask, segment  # noqa: E402
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


def _saga(exe: str, *args: str) -> None:
    """Run one saga_cmd call; raise RuntimeError with SAGA's own message when it fails."""
    proc = subprocess.run([exe, "-f=q", *args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"saga_cmd {' '.join(args[:2])} failed: {(proc.stdout + proc.stderr).strip()[-1500:]}")


def _to_sgrd(exe: str, data: np.ndarray, grid, stem: Path) -> str:
    """Write ``data`` (float32, NaN = no data) as GeoTIFF and import it as a SAGA grid.

    SAGA's tools 2 and 3 need all inputs on one SAGA grid system; GeoTIFFs opened by
    GDAL on the fly and the ``.sdat`` seeds written by tool 2 do not always match
    ("could not initialize data objects"), so every input becomes a native ``.sgrd``.
    """
    write_raster(stem.with_suffix(".tif"), data.astype(np.float32), grid)
    _saga(exe, "io_gdal", "0", "-FILES", str(stem.with_suffix(".tif")), "-GRIDS", str(stem.with_suffix(".sgrd")))
    return str(stem.with_suffix(".sgrd"))


def _read_saga_segments(path: Path, valid: np.ndarray) -> np.ndarray:
    """SAGA segment ids (0-based seed index) as labels 1..n, 0 outside ``valid``."""
    with rasterio.open(path.with_suffix(".sdat")) as src:
        seg = src.read(1, masked=True)
    labels = np.where(np.ma.getmaskarray(seg) | ~np.isfinite(seg.filled(np.nan)), 0, seg.filled(-1).astype(np.int64) + 1)
    return np.where(valid, labels, 0)


def run_saga(exe: str, feats: np.ndarray, valid: np.ndarray, our_seeds: np.ndarray, grid, bandwidth: int, workdir: Path) -> dict:
    """SAGA Seed Generation (tool 2) + Seeded Region Growing (tool 3) on the same features.

    Tool 3 runs with SAGA's own seeds and with our seeds (isolates the growing).  SAGA
    compares candidates with the seed cell's features (its seed table is never updated;
    REFRESH only redraws the GUI), so our growing in ``reference="seed"`` mode is its
    exact counterpart.
    Settings matching ours: variance minima, band-width smoothing, no re-normalisation
    (features are already z-normalised), 4-neighbourhood, feature-space distance only,
    no similarity threshold.  Returns labels, seed counts and seconds per step.
    """
    t0 = time.perf_counter()
    paths = [_to_sgrd(exe, np.where(valid, feats[..., k], np.nan), grid, workdir / f"feature_{k}") for k in range(feats.shape[-1])]
    ours = _to_sgrd(exe, np.where(our_seeds > 0, our_seeds, np.nan), grid, workdir / "our_seeds")
    out = {"import_s": time.perf_counter() - t0}
    flist = ";".join(paths)
    t0 = time.perf_counter()
    _saga(exe, "imagery_segmentation", "2", "-FEATURES", flist, "-VARIANCE", str(workdir / "variance.sgrd"),
          "-SEED_GRID", str(workdir / "seeds.sgrd"), "-SEED_TYPE", "0", "-METHOD", "0",
          "-BAND_WIDTH", str(bandwidth), "-NORMALIZE", "0")
    out["seeds_s"] = time.perf_counter() - t0
    with rasterio.open(workdir / "seeds.sdat") as src:
        s = src.read(1, masked=True)
    out["n_seeds"] = int(np.count_nonzero(~np.ma.getmaskarray(s) & valid))
    for tag, seeds in (("saga", str(workdir / "seeds.sgrd")), ("ours", ours)):
        seg = workdir / f"segments_{tag}.sgrd"
        t0 = time.perf_counter()
        _saga(exe, "imagery_segmentation", "3", "-SEEDS", seeds, "-FEATURES", flist, "-SEGMENTS", str(seg),
              "-SIMILARITY", str(workdir / f"similarity_{tag}.sgrd"), "-TABLE", str(workdir / f"seeds_{tag}.txt"),
              "-NORMALIZE", "0", "-NEIGHBOUR", "0", "-METHOD", "1", "-SIG_1", "1", "-SIG_2", "1", "-THRESHOLD", "0")
        out[f"grow_{tag}_s"] = time.perf_counter() - t0
        out[f"labels_{tag}"] = _read_saga_segments(seg, valid)
    return out


def _contingency(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sparse contingency table of two label rasters over cells labelled in both: (n_ij, a_i, b_j)."""
    ok = (a > 0) & (b > 0)
    a = a[ok].astype(np.int64)
    b = b[ok].astype(np.int64)
    key = a * (int(b.max()) + 1) + b
    pairs, n_ij = np.unique(key, return_counts=True)
    ia, ib = pairs // (int(b.max()) + 1), pairs % (int(b.max()) + 1)
    return n_ij, ia, ib


def adjusted_rand_index(a: np.ndarray, b: np.ndarray) -> float:
    """Adjusted Rand index (Hubert & Arabie 1985) of two segmentations; 1 = identical. O(N log N)."""
    n_ij, ia, ib = _contingency(a, b)
    comb = lambda x: x.astype(np.float64) * (x - 1) / 2.0  # noqa: E731
    n = n_ij.sum()
    sum_ij = comb(n_ij).sum()
    sum_a = comb(np.bincount(ia, weights=n_ij)).sum()
    sum_b = comb(np.bincount(ib, weights=n_ij)).sum()
    expected = sum_a * sum_b / comb(np.array(n))
    top = 0.5 * (sum_a + sum_b)
    return float((sum_ij - expected) / (top - expected)) if top != expected else 1.0


def best_match_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Area-weighted mean over segments of ``a`` of the best IoU with any segment of ``b``."""
    n_ij, ia, ib = _contingency(a, b)
    size_a = np.bincount(ia, weights=n_ij)
    size_b = np.bincount(ib, weights=n_ij)
    iou = n_ij / (size_a[ia] + size_b[ib] - n_ij)
    best = np.zeros(size_a.size)
    np.maximum.at(best, ia, iou)
    return float((best * size_a).sum() / size_a.sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default=str(REPO / "config" / "sites" / "kamech_twin.yaml"))
    ap.add_argument("--scene", type=int, default=0, help="index of the scene in obia.scenes.list")
    ap.add_argument("--no-install", action="store_true", help="do not apt-get install saga")
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "obia"))
    args = ap.parse_args()

    from skimage.metrics import variation_of_information
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

    def add(method: str, labels: np.ndarray, seconds: float, seeds: int | None = None, note: str = "") -> None:
        lab = np.where(valid, labels, 0).astype(np.int64)
        ours = ref.segments.astype(np.int64)
        rows.append({
            "method": method, "time_s": seconds, "seeds": seeds,
            "segments": int(len(np.unique(lab[lab > 0]))),
            "mean_segment_area_m2": float((lab > 0).sum() * scene.grid.cell ** 2 / max(len(np.unique(lab[lab > 0])), 1)),
            "adjusted_rand_index_vs_ours": adjusted_rand_index(ours, lab),
            "best_match_iou_vs_ours": best_match_iou(ours, lab),
            "variation_of_information_vs_ours": float(sum(variation_of_information(ours, lab))),
            "classification_oa_pct": score(lab),
            "note": note,
        })
        print({k: v for k, v in rows[-1].items()}, flush=True)

    seg = segment(rgb[0], rgb[1], rgb[2], scene.dem, scene.grid.cell, valid, params)  # classify_scene's first phase
    feats, seeds, labels = seg.features, seg.seeds, seg.segments
    t_seeds = seg.timings_s["features"] + seg.timings_s["seeds"]
    t_grow = seg.timings_s["growing"]
    add(f"kitegully SRG (seeds + numba growing, reference={params.growing_reference})", labels, t_seeds + t_grow, int(seeds.max()),
        f"features+seeds {t_seeds:.2f} s, growing {t_grow:.2f} s")

    exe = ensure_saga(not args.no_install)
    if exe:
        with tempfile.TemporaryDirectory() as tmp:
            try:
                got = run_saga(exe, feats, valid, seeds, scene.grid, params.seed_bandwidth_cells, Path(tmp))
            except RuntimeError as exc:
                print(f"SAGA comparison failed: {exc}")
                got = None
        if got is not None:
            add("SAGA imagery_segmentation 2 + 3", got["labels_saga"], got["seeds_s"] + got["grow_saga_s"], got["n_seeds"],
                f"seeds {got['seeds_s']:.2f} s, growing {got['grow_saga_s']:.2f} s (+ {got['import_s']:.2f} s GeoTIFF->sgrd import, not counted)")
            add("SAGA imagery_segmentation 3 from our seeds", got["labels_ours"], got["grow_ours_s"], int(seeds.max()),
                "isolates the growing step: same seeds, SAGA's growing (distance to the seed cell)")
            t0 = time.perf_counter()
            lab_seed, _ = seeded_region_growing(feats, seeds, valid, params.position_weight, reference="seed")
            t_seed = time.perf_counter() - t0
            add("kitegully SRG, reference=seed (SAGA's rule)", lab_seed, t_seed, int(seeds.max()),
                f"growing only; agreement with SAGA from our seeds: ARI {adjusted_rand_index(got['labels_ours'], lab_seed):.4f}, "
                f"best-match IoU {best_match_iou(got['labels_ours'], lab_seed):.4f}")
    else:
        print("SAGA GIS not available: comparison skipped")

    img = np.moveaxis(scene.rgb, 0, -1).astype(np.float64) / 255.0
    t0 = time.perf_counter()
    lab = slic(img, n_segments=int(seeds.max()), compactness=10.0, start_label=1, mask=valid)
    add("scikit-image SLIC", lab, time.perf_counter() - t0, None, "RGB only, n_segments = our seed count, compactness 10")
    t0 = time.perf_counter()
    lab = felzenszwalb(img, scale=100, sigma=0.5, min_size=50) + 1
    add("scikit-image Felzenszwalb", lab, time.perf_counter() - t0, None, "RGB only, scale 100, sigma 0.5, min_size 50")

    out = Path(args.out)
    write_table(pd.DataFrame(rows), out / "obia_benchmark.csv", floatfmt=".3g")
    print((out / "obia_benchmark.md").read_text())


if __name__ == "__main__":
    main()
