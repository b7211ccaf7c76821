"""Time one SfM mapper (incremental, global, hierarchical) on an existing match database.

Issue 21: the full-size Kamech survey (~750 photos) asks which mapper to use. This script
copies nothing: give it a COPY of an SfM stage's ``work/database.db`` (features and
verified matches already in it) and its ``work/images`` folder, and it runs
:func:`kitegully.sfm.reconstruct.map_model` exactly as the stage does (same options, same
self-calibration, same final bundle adjustment), then prints and appends one CSV row:
mapper, registered images, 3-D points, mean track length, mean reprojection error (px),
focal length (px), wall time and CPU time (s; on a shared machine CPU time is the
comparable one). Wrap it in ``/usr/bin/time -v`` for peak memory.

``--global-ba-growth G`` sets how often the incremental mapper adjusts the whole model
(``sfm.global_ba_growth``). ``--truth-poses`` (a twin's ``flight/truth/poses.csv``,
evaluation only) fits a seven-parameter similarity from the model's camera centres to the
true ones (``--image-info``: the stage's ``image_info.json``, which names the prepared
copies) and adds its RMS and largest residual (m): the block's shape (drift, dome)
before any ground control, the same for every mapper setting.

    nice -n 15 /usr/bin/time -v .venv/bin/python benchmarks/sfm_mappers.py \\
        DB IMAGES OUT_DIR --mapper global --threads 1 --csv benchmarks/out/sfm_mappers.csv

A database is written to by COLMAP's global mapper (it stores the decomposed relative
poses); run each mapper on its own copy when the original must stay unchanged.
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import shutil
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap

from kitegully.georef.similarity import umeyama
from kitegully.sfm.reconstruct import DEFAULT_GLOBAL_BA_GROWTH, MAPPERS, map_model


def shape_against_truth(rec: pycolmap.Reconstruction, poses_csv: Path, photo_names: dict[str, str] | None = None) -> dict:
    """RMS and largest residual (m) of the model's camera centres after a similarity onto the truth.

    ``photo_names`` maps the model's image names (the SfM stage's prepared copies,
    ``image_info.json``'s ``sfm_name``) to the photos' names in ``poses_csv``; without it
    the names are matched as they are. Both sides are compared by file stem.
    """
    truth = pd.read_csv(poses_csv)
    truth.index = [Path(str(n)).stem for n in truth["image"]]
    names = photo_names or {}
    model = {Path(names.get(im.name, im.name)).stem: im.projection_center()
             for im in rec.images.values() if im.has_pose}
    common = [k for k in model if k in truth.index]
    a = np.array([model[k] for k in common])
    b = truth.loc[common, ["x_m", "y_m", "z_m"]].to_numpy(float)
    r = np.linalg.norm(umeyama(a, b).apply(a) - b, axis=1)
    return {"n_truth_matched": len(common), "shape_rms_m": round(float(np.sqrt(np.mean(r**2))), 4),
            "shape_max_m": round(float(r.max()), 4)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("database", type=Path)
    ap.add_argument("images", type=Path)
    ap.add_argument("out", type=Path, help="model folder to write")
    ap.add_argument("--mapper", choices=MAPPERS, default="incremental")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--refine-principal-point", action="store_true", default=True)
    ap.add_argument("--min-num-matches", type=int, default=15)
    ap.add_argument("--global-ba-growth", type=float, default=DEFAULT_GLOBAL_BA_GROWTH)
    ap.add_argument("--truth-poses", type=Path, default=None, help="a twin's flight/truth/poses.csv (evaluation)")
    ap.add_argument("--image-info", type=Path, default=None,
                    help="the SfM stage's image_info.json: prepared copy names -> photo names (with --truth-poses)")
    ap.add_argument("--label", default="")
    ap.add_argument("--csv", type=Path, default=None)
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    db = a.out.parent / (a.out.name + "_database.db")
    shutil.copy(a.database, db)  # the global mapper writes relative poses into its database
    pycolmap.set_random_seed(a.seed)
    t0, c0 = time.perf_counter(), time.process_time()
    rec = map_model(db, a.images, a.out, a.refine_principal_point, a.min_num_matches, a.seed, a.threads,
                    mapper=a.mapper, global_ba_growth=a.global_ba_growth)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    cam = next(iter(rec.cameras.values()))
    row = {
        "label": a.label, "mapper": a.mapper, "global_ba_growth": a.global_ba_growth, "threads": a.threads,
        "n_images_db": pycolmap.Database.open(str(db)).num_images(),
        "n_registered": rec.num_reg_images(), "n_points3d": rec.num_points3D(),
        "mean_track_length": round(rec.compute_mean_track_length(), 3),
        "mean_reprojection_error_px": round(rec.compute_mean_reprojection_error(), 4),
        "focal_px": round(float(cam.params[0]), 2), "k1": round(float(cam.params[3]), 6),
        "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
    }
    if a.truth_poses:
        names = {i["sfm_name"]: i["name"] for i in json.loads(a.image_info.read_text())} if a.image_info else None
        row.update(shape_against_truth(rec, a.truth_poses, names))
    db.unlink()
    print(row)
    if a.csv:
        a.csv.parent.mkdir(parents=True, exist_ok=True)
        new = not a.csv.exists()
        with a.csv.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(row))
            if new:
                w.writeheader()
            w.writerow(row)


if __name__ == "__main__":
    main()
