"""Verified matches per image pair by sensor pair (RGB-RGB, RGB-NIR, NIR-NIR), paper 004's Table 2."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

#: Paper 004's Table 2: pairs matched and mean matches per matched pair, by sensor pair.
PAPER_MATCHES = {"RGB-RGB": (4454, 854.6), "RGB-NIR": (3063, 188.2), "NIR-NIR": (2630, 1106.2)}
#: COLMAP's pair identifier: ``pair_id = image_id1 * MAX_IMAGE_ID + image_id2``.
MAX_IMAGE_ID = 2147483647


def matches_by_pair_type(database: str | Path, sfm_to_name: Mapping[str, str], min_num_matches: int) -> pd.DataFrame:
    """Verified (two-view geometry inlier) matches per image pair, by sensor pair type.

    The paper's table counts pairs that matched and their mean matches; pairs with at least
    ``min_num_matches`` inliers are counted here. O(pairs).

    Parameters
    ----------
    database : path
        COLMAP database of the SfM run.
    sfm_to_name : mapping
        SfM image name to original image name; a name starting with ``nir`` marks a NIR photo.
    min_num_matches : int
        Fewest inlier matches for a pair to count as matched.

    Returns
    -------
    DataFrame
        One row per pair type (RGB-RGB, RGB-NIR, NIR-NIR): pairs tested, pairs matched, mean
        matches per matched pair and the paper's values.
    """
    con = sqlite3.connect(str(database))
    try:
        names = dict(con.execute("SELECT image_id, name FROM images").fetchall())
        geo = con.execute("SELECT pair_id, rows FROM two_view_geometries").fetchall()
    finally:
        con.close()

    def sensor(image_id: int) -> str:
        n = sfm_to_name.get(names[image_id], names[image_id])
        return "NIR" if Path(n).name.lower().startswith("nir") else "RGB"

    n_by = {"RGB": sum(1 for i in names if sensor(i) == "RGB"), "NIR": sum(1 for i in names if sensor(i) == "NIR")}
    counts: dict[str, list[int]] = {k: [] for k in PAPER_MATCHES}
    for pair_id, rows in geo:
        i2 = pair_id % MAX_IMAGE_ID
        i1 = (pair_id - i2) // MAX_IMAGE_ID
        a, b = sorted((sensor(i1), sensor(i2)), key=lambda s: s != "RGB")
        if rows >= min_num_matches:
            counts[f"{a}-{b}"].append(int(rows))
    out = []
    for k, v in counts.items():
        a, b = k.split("-")
        all_pairs = n_by[a] * (n_by[a] - 1) // 2 if a == b else n_by[a] * n_by[b]
        out.append({"pair_type": k, "pairs_tested": all_pairs, "pairs_matched": len(v),
                    "mean_matches_per_matched_pair": float(np.mean(v)) if v else 0.0,
                    "paper_pairs_matched": PAPER_MATCHES[k][0], "paper_mean_matches": PAPER_MATCHES[k][1]})
    return pd.DataFrame(out)
