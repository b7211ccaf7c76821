"""Twin-site evaluation of SfM + georeferencing against the flight truth (evaluation only).

Targets of issue 5 for the default twin, in ground sampling distances (GSD, the median
GSD of the rendered images): all images registered, camera positions within 2 GSD of
truth, GCP RMSE ≤ 1 GSD horizontally and ≤ 1.5 GSD vertically, leave-one-out RMSE ≤ 2 GSD.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from pathlib import Path


def evaluate_twin(cameras: pd.DataFrame, truth_poses: pd.DataFrame, residuals: pd.DataFrame, loo: pd.DataFrame,
                  gsd_m: float, n_images: int) -> tuple[pd.DataFrame, dict]:
    """Per-image camera position errors and the target checks.

    ``cameras`` has ``image, x_m, y_m, z_m`` (estimated, site CRS); ``truth_poses`` the
    same columns from ``flight/truth/poses.csv``.

    Parameters
    ----------
    cameras : DataFrame
        Estimated camera positions (site CRS, m).
    truth_poses : DataFrame
        True camera positions (site CRS, m).
    residuals : DataFrame
        GCP residuals after the adjustment (columns ``used``, ``dx_m``, ``dy_m``, ``dz_m``).
    loo : DataFrame
        Leave-one-out residuals (column ``d3_m``).
    gsd_m : float
        Ground sampling distance the targets are expressed in (m).
    n_images : int
        Number of images of the flight.

    Returns
    -------
    table : DataFrame
        ``image``, ``dx_m``, ``dy_m``, ``dz_m``, ``d3_m`` and ``d3_gsd`` of each image in both tables.
    summary : dict
        Image counts, camera and GCP RMSEs (m), the leave-one-out RMSE (m), the target checks
        and ``all_targets_met``.
    """
    t = truth_poses.set_index("image")[["x_m", "y_m", "z_m"]]
    c = cameras.set_index("image")[["x_m", "y_m", "z_m"]]
    common = c.index.intersection(t.index)
    d = c.loc[common] - t.loc[common]
    table = pd.DataFrame({
        "image": common, "dx_m": d["x_m"].to_numpy(), "dy_m": d["y_m"].to_numpy(), "dz_m": d["z_m"].to_numpy(),
    })
    table["d3_m"] = np.sqrt(table["dx_m"] ** 2 + table["dy_m"] ** 2 + table["dz_m"] ** 2)
    table["d3_gsd"] = table["d3_m"] / gsd_m
    u = residuals[residuals["used"]]

    def rmse(v):
        v = np.asarray(v, float)
        v = v[np.isfinite(v)]
        return float(np.sqrt(np.mean(v**2))) if len(v) else float("nan")

    gcp_h = rmse(np.hypot(u["dx_m"], u["dy_m"]))
    gcp_v = rmse(u["dz_m"])
    loo3 = rmse(loo["d3_m"])
    summary = {
        "gsd_m": gsd_m,
        "n_images": int(n_images),
        "n_registered": int(len(c)),
        "camera_max_error_m": float(table["d3_m"].max()) if len(table) else float("nan"),
        "camera_rmse_m": rmse(table["d3_m"]),
        "gcp_rmse_h_m": gcp_h,
        "gcp_rmse_v_m": gcp_v,
        "loo_rmse_3d_m": loo3,
    }
    summary["targets"] = {
        "all_images_registered": summary["n_registered"] == n_images,
        "cameras_within_2_gsd": bool(len(table) and table["d3_gsd"].max() <= 2.0),
        "gcp_h_within_1_gsd": bool(gcp_h <= gsd_m),
        "gcp_v_within_1.5_gsd": bool(gcp_v <= 1.5 * gsd_m),
        "loo_within_2_gsd": bool(loo3 <= 2 * gsd_m),
    }
    summary["all_targets_met"] = all(summary["targets"].values())
    return table, summary


def evaluate_against_flight_truth(cameras_gpkg: str | Path, poses_csv: str | Path, image_stats_csv: str | Path,
                                  residuals_csv: str | Path, loo_csv: str | Path, sfm_summary_json: str | Path,
                                  table_csv: str | Path, summary_json: str | Path) -> dict:
    """Twin only (evaluation): the georef stage's products against the flight truth, written out.

    Parameters
    ----------
    cameras_gpkg, residuals_csv, loo_csv : path
        The georef stage's camera positions and GCP / leave-one-out residual tables.
    poses_csv, image_stats_csv : path
        The flight truth: camera poses and the rendered images' statistics (``gsd_m``; the
        median is the GSD the targets are expressed in).
    sfm_summary_json : path
        The SfM summary (``n_images``).
    table_csv, summary_json : path
        Outputs: per-image camera errors and the target checks.

    Returns
    -------
    dict
        The summary written to ``summary_json``.
    """
    import json

    from kitegully.georef.export import clean_json
    from kitegully.io.tables import write_table
    from kitegully.io.vectors import read_vector

    cams = read_vector(cameras_gpkg)
    gsd = float(pd.read_csv(image_stats_csv)["gsd_m"].median())
    sfm = json.loads(open(sfm_summary_json, encoding="utf-8").read())
    table, summary = evaluate_twin(
        pd.DataFrame(cams.drop(columns="geometry")), pd.read_csv(poses_csv), pd.read_csv(residuals_csv),
        pd.read_csv(loo_csv), gsd, sfm["n_images"],
    )
    write_table(table, table_csv)
    with open(summary_json, "w", encoding="utf-8") as fh:
        json.dump(clean_json(summary), fh, indent=2)
    return summary
