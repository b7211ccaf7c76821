"""Time one SfM mapper (incremental, global, hierarchical) on an existing match database.

Issue 21: the full-size Kamech survey (~750 photos) asks which mapper to use. This script
copies nothing: give it a COPY of an SfM stage's ``work/database.db`` (features and
verified matches already in it) and its ``work/images`` folder, and it runs
:func:`kitegully.sfm.reconstruct.map_model` exactly as the stage does (same options, same
self-calibration, same final bundle adjustment), then prints and appends one CSV row:
mapper, registered images, 3-D points, mean track length, mean reprojection error (px),
focal length (px), wall time and CPU time (s; on a shared machine CPU time is the
comparable one). Wrap it in ``/usr/bin/time -v`` for peak memory.

    nice -n 15 /usr/bin/time -v .venv/bin/python benchmarks/sfm_mappers.py \\
        DB IMAGES OUT_DIR --mapper global --threads 1 --csv benchmarks/out/sfm_mappers.csv

A database is written to by COLMAP's global mapper (it stores the decomposed relative
poses); run each mapper on its own copy when the original must stay unchanged.
"""

from __future__ import annotations

import argparse
import csv
import logging
import shutil
import time
from pathlib import Path

import pycolmap

from kitegully.sfm.reconstruct import MAPPERS, map_model


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
    ap.add_argument("--label", default="")
    ap.add_argument("--csv", type=Path, default=None)
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    db = a.out.parent / (a.out.name + "_database.db")
    shutil.copy(a.database, db)  # the global mapper writes relative poses into its database
    pycolmap.set_random_seed(a.seed)
    t0, c0 = time.perf_counter(), time.process_time()
    rec = map_model(db, a.images, a.out, a.refine_principal_point, a.min_num_matches, a.seed, a.threads,
                    mapper=a.mapper)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    cam = next(iter(rec.cameras.values()))
    row = {
        "label": a.label, "mapper": a.mapper, "threads": a.threads,
        "n_images_db": pycolmap.Database.open(str(db)).num_images(),
        "n_registered": rec.num_reg_images(), "n_points3d": rec.num_points3D(),
        "mean_track_length": round(rec.compute_mean_track_length(), 3),
        "mean_reprojection_error_px": round(rec.compute_mean_reprojection_error(), 4),
        "focal_px": round(float(cam.params[0]), 2), "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
    }
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
