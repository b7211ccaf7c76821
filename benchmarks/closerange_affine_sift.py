"""Plain against affine-covariant SIFT on one close-range scene's photos (issue 20, scene 08).

Runs the sfm stage's ``reconstruct_model`` on a scene's pole photos as ``closerange_sfm``
does (exhaustive matching, ``closerange.sfm_max_num_features``), once per variant, and
prints photos registered, tie points, verified matches between photos by their index step
around the ring, and the time of each SfM step (the ratio between variants is the cost).

Usage (repository root, PYTHONPATH=src; photos from ``closerange_photos``):
    python benchmarks/closerange_affine_sift.py results/kamech_twin/closerange/scenes/scene_08/photos \
        --variants plain affine --out /tmp/cr_affine
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pycolmap
import yaml

from kitegully.sfm.stage import SfmParams, reconstruct_model

REPO = Path(__file__).resolve().parents[1]
VARIANTS = {
    "plain": {},
    "affine": {"estimate_affine_shape": True, "domain_size_pooling": True, "guided_matching": True},
    "affine_only": {"estimate_affine_shape": True},
    "guided": {"guided_matching": True},
}


def links(database: Path, n: int) -> dict:
    """Median verified matches between photos k steps apart around the ring (k = 1, 2, 3) and the weak links."""
    db = pycolmap.Database.open(str(database))
    try:
        ids = {im.image_id: int(Path(im.name).stem.split("_")[-1]) for im in db.read_all_images()}
        pairs, geoms = db.read_two_view_geometries()
    finally:
        db.close()
    m = np.zeros((n, n), int)
    for pid, g in zip(pairs, geoms):
        a, b = pycolmap.pair_id_to_image_pair(pid)
        i, j = ids[a], ids[b]
        m[i, j] = m[j, i] = len(g.inlier_matches)
    out = {}
    for k in (1, 2, 3):
        v = np.array([m[i, (i + k) % n] for i in range(n)])
        out[f"step{k}_median"] = float(np.median(v))
        out[f"step{k}_below_100"] = int((v < 100).sum())
    return out


KEYS = ("n_images", "n_registered", "n_points3d", "mean_reprojection_error_px", "features_s", "matching_s", "mapping_s")


def run_variant(photos: str, cfg: dict, variant: str, out: Path) -> dict:
    """SfM of the photos as closerange_sfm runs it, with the variant's sfm keys; the summary's main numbers."""
    s = dict(cfg["sfm"], max_num_features=cfg["closerange"]["sfm_max_num_features"], **VARIANTS[variant])
    s["matching"] = dict(s["matching"], camera_log=None, method="exhaustive")
    t0 = time.perf_counter()
    try:
        summ = reconstruct_model(photos, out / "work", out / "model", out / "summary.json", out / "images.csv",
                                 out / "image_info.json", SfmParams.from_config(s), cfg["seed"], 2)
        row = {k: summ[k] for k in KEYS}
    except Exception as err:  # noqa: BLE001 - a variant that builds no model is a result
        row = {"error": str(err)}
    row["total_s"] = time.perf_counter() - t0
    return row


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("photos")
    ap.add_argument("--site", default="kamech_twin")
    ap.add_argument("--variants", nargs="+", default=["plain", "affine"])
    ap.add_argument("--out", default="/tmp/closerange_affine")
    ap.add_argument("--links-only", action="store_true", help="only read the ring links of an earlier run's databases")
    a = ap.parse_args()
    cfg = yaml.safe_load((REPO / "config" / "sites" / f"{a.site}.yaml").read_text())
    rows = {}
    for v in a.variants:
        out = Path(a.out) / v
        out.mkdir(parents=True, exist_ok=True)
        if a.links_only:
            summ = json.loads((out / "summary.json").read_text())
            row = {k: summ[k] for k in KEYS if k in summ}
        else:
            row = run_variant(a.photos, cfg, v, out)
        row.update(links(out / "work" / "database.db", len(list(Path(a.photos).glob("*.JPG")))))
        rows[v] = row
        print(v, json.dumps(row), flush=True)
    (Path(a.out) / "summary.json").write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
