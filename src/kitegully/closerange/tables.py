"""The closerange stage's summary (rule ``closerange_summary``): 001 Table 1 per scene next to the
paper's, and the OBIA accuracy on the photogrammetric orthophotos next to the direct renders'
and the paper's (Mayr et al. 2016, Tables 1 and 3); failed scenes are rows with their sentence.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

log = logging.getLogger(__name__)

#: 001 Table 1 (scenes 1-10): images used / aligned, marker error (m), scale error (%; None: no rule in scene 6).
PAPER_TABLE1 = pd.DataFrame({
    "scene": [f"scene_{i:02d}" for i in range(1, 11)],
    "paper_images_used": [613, 539, 676, 480, 342, 243, 179, 279, 406, 251],
    "paper_images_aligned": [546, 484, 505, 342, 234, 233, 143, 275, 399, 250],
    "paper_marker_error_m": [0.03, 0.03, 0.01, 0.08, 0.16, 0.04, 0.02, 0.03, 0.03, 0.03],
    "paper_scale_error_pct": [1, 2, 3, 1, 6, np.nan, 1, 1, 2, 2],
})
#: 001 Table 3 overall accuracy per scene (%) and over all scenes.
PAPER_OA = dict(zip([f"scene_{i:02d}" for i in range(1, 11)], [95.4, 95.4, 92.8, 94.5, 90.7, 94.3, 92.6, 94.3, 93.3, 95.5]))
PAPER_OA["all"] = 94.3


def failed_scene_record(scene: str, reason: str) -> dict:
    """The record of a scene that could not be georeferenced (``on_scene_failure: record``).

    Parameters
    ----------
    scene : scene name.
    reason : the InputError's one sentence.

    Returns
    -------
    dict
        ``{"scene", "status": "failed", "reason"}``; :func:`closerange_tables` lists it as a
        row without numbers and leaves it out of the means and the overall accuracy.
    """
    return {"scene": scene, "status": "failed", "reason": str(reason)}


def scene_succeeded(record: Mapping[str, Any]) -> bool:
    """Whether a ``closerange.json`` record is a georeferenced scene (records without ``status`` are)."""
    return record.get("status", "ok") == "ok"


@dataclass
class CloseRangeTables:
    """Products of :func:`closerange_tables`."""

    table1: pd.DataFrame
    accuracy: pd.DataFrame


def closerange_tables(
    records: Sequence[dict], confusion_sfm: Sequence[dict], confusion_direct: Sequence[dict],
    same_cells: Sequence[tuple[str, str, str]] = (),
) -> CloseRangeTables:
    """001 Table 1 per scene next to the paper's, and OBIA accuracy on the photogrammetric vs the direct orthophotos.

    ``records`` are the :func:`photogrammetric_orthophoto` records of all requested scenes,
    failed ones included (:func:`failed_scene_record`); the confusions are the obia stage's
    ``confusion.json`` records of the scenes that succeeded (photogrammetric and direct
    renders).  Both tables have ``status`` and ``reason`` columns: a failed scene is a row
    with its sentence and no numbers.  Each table ends with an ``all`` row over the scenes
    that succeeded (means for Table 1, the paper's too, over the same scenes; summed
    confusion matrices for the accuracy), whose ``status`` states the count ("8 of 10
    scenes").  ``same_cells`` gives per succeeded scene the paths of the direct and the
    photogrammetric classification and the truth mask: the direct classification is then
    also scored on the cells the photogrammetric one covers (``oa_direct_same_cells_pct``),
    which separates the effect of the crop from that of the SfM defects.

    Parameters
    ----------
    records : sequence of dict
        Scene records, failed ones included.
    confusion_sfm, confusion_direct : sequence of dict
        Confusion records of the succeeded scenes on the photogrammetric and the direct orthophotos.
    same_cells : sequence of (str, str, str)
        Paths of the direct classification, the photogrammetric classification and the truth mask, in the order
        of ``confusion_sfm``; empty to skip the same-cells score.

    Returns
    -------
    CloseRangeTables
        ``table1`` (Table 1 per scene) and ``accuracy`` (OBIA accuracy per scene), each with an ``all`` row.
    """
    from kitegully.io.raster import read_raster
    from kitegully.obia.accuracy import accuracies, confusion_matrix

    ok_recs = [r for r in records if scene_succeeded(r)]
    failed = [r for r in records if not scene_succeeded(r)]
    count = f"{len(ok_recs)} of {len(records)} scenes"
    failed_note = "" if not failed else "failed: " + ", ".join(r["scene"] for r in failed)
    t1 = pd.DataFrame([{
        "scene": r["scene"], "status": "ok", "reason": "", "images_used": r["images_used"], "images_aligned": r["images_aligned"],
        "marker_error_m": r["marker_error_m"], "spheres_measured": r["spheres_measured"],
        "scale_error_pct": np.nan if r["scale_error_pct"] is None else r["scale_error_pct"],
        "leg_a_m": np.nan if r["rule"] is None else r["rule"]["leg_a_m"],
        "leg_b_m": np.nan if r["rule"] is None else r["rule"]["leg_b_m"],
        "rule_method": r.get("rule_method") or ("" if r["rule"] is None else "orthophoto"),
        "sift": r.get("sift", "plain").split(" ")[0],
        "tie_points": r["tie_points"], "dense_points": r["dense_points"], "holes_pct": r["holes_pct"],
        "time_s": r["timings_s"]["total"],
    } if scene_succeeded(r) else {"scene": r["scene"], "status": "failed", "reason": r["reason"]} for r in records])
    if len(t1):
        t1 = t1.merge(PAPER_TABLE1, on="scene", how="left")
        ok = t1["status"] == "ok"
        mean = {c: t1.loc[ok, c].mean() for c in t1.columns if c not in ("scene", "status", "reason", "rule_method", "sift")}
        n_affine = int((t1.loc[ok, "sift"] == "affine").sum())
        t1.loc[len(t1)] = {"scene": "all", "status": count, "reason": failed_note, "sift": f"affine in {n_affine}", **mean}
        t1 = t1[[c for c in t1.columns if c != "reason"] + ["reason"]]  # the sentence last: the .md stays readable

    def acc_row(scene, conf):
        a = accuracies(np.asarray(conf))
        return {"oa": 100 * a["overall"], "ua_eroded": 100 * a["users"][1], "pa_eroded": 100 * a["producers"][1]}

    direct = {c["scene"]: c for c in confusion_direct}
    sfm = {c["scene"]: c for c in confusion_sfm}
    same = {}
    for (direct_path, sfm_path, truth_path), c in zip(same_cells, confusion_sfm):
        dc, _ = read_raster(direct_path)
        sc, _ = read_raster(sfm_path)
        tr, _ = read_raster(truth_path)
        same[c["scene"]] = confusion_matrix(dc, tr, valid=(sc != 255) & (dc != 255))
    rows, tot_s, tot_d, tot_x = [], np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2))
    for r in records:
        if not scene_succeeded(r):
            rows.append({"scene": r["scene"], "status": "failed", "reason": r["reason"], "oa_paper_pct": PAPER_OA.get(r["scene"])})
            continue
        c, d = sfm[r["scene"]], direct[r["scene"]]
        tot_s += np.asarray(c["confusion"])
        tot_d += np.asarray(d["confusion"])
        x_ = acc_row(c["scene"], same[c["scene"]])["oa"] if c["scene"] in same else np.nan
        if c["scene"] in same:
            tot_x += same[c["scene"]]
        s_, d_ = acc_row(c["scene"], c["confusion"]), acc_row(c["scene"], d["confusion"])
        rows.append({"scene": c["scene"], "status": "ok", "reason": "",
                     "oa_sfm_pct": s_["oa"], "oa_direct_pct": d_["oa"], "oa_direct_same_cells_pct": x_,
                     "oa_paper_pct": PAPER_OA.get(c["scene"]),
                     "ua_eroded_sfm_pct": s_["ua_eroded"], "pa_eroded_sfm_pct": s_["pa_eroded"],
                     "ua_eroded_direct_pct": d_["ua_eroded"], "pa_eroded_direct_pct": d_["pa_eroded"],
                     "area_sfm_m2": c["area_auto_m2"], "area_ref_in_crop_m2": c["area_ref_m2"],
                     "area_direct_m2": d["area_auto_m2"], "area_ref_full_m2": d["area_ref_m2"]})
    if ok_recs:
        s_, d_ = acc_row("all", tot_s), acc_row("all", tot_d)
        rows.append({"scene": "all", "status": count, "reason": failed_note,
                     "oa_sfm_pct": s_["oa"], "oa_direct_pct": d_["oa"],
                     "oa_direct_same_cells_pct": acc_row("all", tot_x)["oa"] if same else np.nan, "oa_paper_pct": PAPER_OA["all"],
                     "ua_eroded_sfm_pct": s_["ua_eroded"], "pa_eroded_sfm_pct": s_["pa_eroded"],
                     "ua_eroded_direct_pct": d_["ua_eroded"], "pa_eroded_direct_pct": d_["pa_eroded"]})
    acc = pd.DataFrame(rows)
    if len(acc):
        acc = acc[[c for c in acc.columns if c != "reason"] + ["reason"]]
    for r in failed:
        log.info("%s: failed, not in the overall accuracy: %s", r["scene"], r["reason"])
    if ok_recs:
        log.info("OBIA: OA %.1f %% over %s on the photogrammetric orthophotos, %.1f %% on the direct renders of the same "
                 "scenes (paper 94.3 %% over 10)", acc["oa_sfm_pct"].iloc[-1], count, acc["oa_direct_pct"].iloc[-1])
    else:
        log.info("OBIA: no scene of %d was georeferenced; no overall accuracy", len(records))
    return CloseRangeTables(t1, acc)
