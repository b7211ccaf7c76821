"""Where the folding rule's scale error comes from, per photo and per leg end (issue 20; evaluation only).

For every scene with a rule, on the stored products of a ``make closerange`` run (photos,
COLMAP model, DEM; read only), the rule is measured again as ``closerange_sfm`` measures it
(:func:`kitegully.closerange.rule_photos.measure_rule_in_photos`'s steps, same random
streams) and compared with the twin's truth (the rebuilt walk: true poses, ideal camera, the
painted rule):

* the *painted* rule: corner and leg ends in plan where the twin painted them, at the
  rendered surface's height (the paint is draped on the DEM; the twin's truth record gives
  the rigid rule's points, on the plane fitted under the corner), and its 3-D leg lengths;
* per photo and per end: the true end projected with the TRUE camera, the end that
  ``find_rule_views`` located, the error along the leg (+ = beyond the true end) and across
  it, in px and in cm on the ground (px × the leg's metres per px in that photo); the
  projection with the SfM camera (the camera's own error, px);
* triangulations of the photos the pipeline used: (a) the pipeline's; (b) the located
  points with the TRUE cameras (localisation error only); (c) the true points projected
  with the SfM cameras (camera error only).

Usage (repository root, PYTHONPATH=src):
    python benchmarks/closerange_rule_diagnosis.py [--results /work/wt/closerange9/results/kamech_twin]
        [--scenes scene_05 ...] [--method current|baseline] [--out benchmarks/out]
Writes ``<out>/closerange_rule_diagnosis_<method>.md`` and ``..._views.csv``.  About a minute
per scene on the loaded 2 cores (the sphere similarity is cached after the first run).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from closerange_rule_scene import REPO, load_scene  # noqa: E402

from kitegully.closerange import rule_photos as rp  # noqa: E402
from kitegully.seeds import rng_for  # noqa: E402
from kitegully.twin.camera import Pose  # noqa: E402
from kitegully.twin.render import surface_height  # noqa: E402

SCENES = [f"scene_{i:02d}" for i in (1, 2, 3, 4, 5, 7, 8, 9, 10)]


def painted_rule(st, rigid: bool = False) -> np.ndarray:
    """(3, 3) photographed A end, corner, B end.

    Session-9 photos: the rule painted on the texture, i.e. the plan position of the twin's
    rule at the rendered surface's height.  ``rigid``: the re-rendered photos' rigid rule.
    """
    P = np.array(st.truth_rule, float).copy()
    if rigid:
        return P
    P[:, 2] = surface_height(st.render, P[:, 0], P[:, 1])
    return P


def ls_point(O, D):
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for o, d in zip(O, D):
        M = np.eye(3) - np.outer(d, d)
        A += M
        b += M @ o
    return np.linalg.solve(A, b)


def true_ray(st, k, uv):
    pose = st.poses[k]
    d = st.camera.rays_camera(np.array([uv[0]]), np.array([uv[1]]))[0] @ pose.R
    return pose.C, d


def sfm_project(st, k, X):
    ph = st.photos[k]
    s = st.sim
    Xm = ((np.atleast_2d(X) - s.t) @ s.R) / s.scale  # survey -> model
    return ph.camera.project(Xm, Pose(ph.R, ph.centre))


def views_of_scene(st, method: str):
    """The L's of every photo, as the stage finds them (same random stream)."""
    rng = rng_for(st.seed, "closerange", st.scene, "rule_photos")
    views = []
    p = st.params
    for k, ph in enumerate(st.photos):
        wmax = rp.strip_width_px(ph.camera.f, p.rule_strip_width_m, p.pole_height_m)
        window = int(np.ceil(4.0 * wmax)) | 1
        f, mask = rp.photo_paint_share(st.images[ph.name], p.rule_paint_rgb, 2.2, window, 0.25)
        views += rp.find_rule_views(f, mask, k, wmax, window, rng, gap_px=5.0 * wmax if method.startswith("baseline") else None)
    return views


def diagnose(st, method: str):
    p = st.params
    t0 = time.perf_counter()
    views = views_of_scene(st, method)
    # as measure_rule_in_photos: the corner tolerance is the strip's width
    res, why = rp.triangulate_rule(views, st.photos, st.sim, st.dem, st.grid, p.rule_strip_width_m, p.outlier_tolerance_m)
    dt = time.perf_counter() - t0
    P = painted_rule(st, rigid=method.endswith("rigid"))  # A, corner, B (twin labels)
    C = P[1]
    rows = []
    for vi, v in enumerate(views):
        k = v.photo
        pose = st.poses[k]
        uvC = st.camera.project(C[None], pose)[0]
        if not np.all(np.isfinite(uvC)) or np.linalg.norm(v.corner_uv - uvC) > 10.0:
            continue  # not the rule's L in this photo (evaluation: 10 px from the true corner)
        uvE = st.camera.project(P[[0, 2]], pose)
        dirs = (uvE - uvC) / np.linalg.norm(uvE - uvC, axis=1, keepdims=True)
        lenpx = np.linalg.norm(uvE - uvC, axis=1)
        row = {"scene": st.scene, "photo": k, "corner_err_px": float(np.linalg.norm(v.corner_uv - uvC)),
               "cam_err_corner_px": float(np.linalg.norm(sfm_project(st, k, C)[0] - uvC)), "width_px": v.width_px}
        for lab in (0, 1):
            dv = v.end_uv[lab] - v.corner_uv
            dv = dv / max(np.linalg.norm(dv), 1e-9)
            j = int(np.argmax(dirs @ dv))  # which true leg this label is
            e = v.end_uv[lab] - uvE[j]
            along = float(e @ dirs[j])
            across = float(e @ np.array([-dirs[j, 1], dirs[j, 0]]))
            dist = float(np.linalg.norm(P[2 * j] - pose.C))
            name = "AB"[lab]
            row.update({
                f"{name}_true_leg": "AB"[j], f"{name}_seen": bool(v.end_seen[lab]),
                f"{name}_used": vi in (res or {}).get("view_ids_corner", []) and k in (res or {}).get(f"photo_ids_{name.lower()}", []),
                f"{name}_along_px": along, f"{name}_across_px": across, f"{name}_along_cm": 100.0 * along / lenpx[j],
                f"{name}_leg_px": float(lenpx[j]), f"{name}_range_m": dist,
                f"{name}_true_inside": bool(st.camera.in_image(uvE[j][None], 0.5 * (int(np.ceil(4 * rp.strip_width_px(800, .02, 3))) | 1))[0]),
                f"{name}_cam_err_px": float(np.linalg.norm(sfm_project(st, k, P[2 * j])[0] - uvE[j])),
            })
        rows.append(row)
    df = pd.DataFrame(rows)
    summ = {"scene": st.scene, "stored_scale_pct": st.record.get("scale_error_pct"), "measure_s": dt,
            "painted_legs_m": [float(np.linalg.norm(P[0] - C)), float(np.linalg.norm(P[2] - C))]}
    if res is None:
        summ["why"] = why
        return summ, df
    summ.update({"scale_pct": res["scale_error_pct"], "legs_m": [res["leg_a_m"], res["leg_b_m"]],
                 "n_corner": res["photos_corner"], "n_a": res["photos_a"], "n_b": res["photos_b"]})
    # triangulations of the used photos with the true cameras (located points) and with the SfM cameras (true points)
    byphoto = {views[m].photo: views[m] for m in res["view_ids_corner"]}

    def tri(ids, which):
        if which == "corner":
            uvs = {k: byphoto[k].corner_uv for k in ids}
        else:
            uvs = {k: byphoto[k].end_uv[which] for k in ids}
        O, D = zip(*(true_ray(st, k, uv) for k, uv in uvs.items()))
        return ls_point(np.array(O), np.array(D))

    Xc = tri(res["photo_ids_corner"], "corner")
    Xa, Xb = tri(res["photo_ids_a"], 0), tri(res["photo_ids_b"], 1)
    summ["truecam_legs_m"] = [float(np.linalg.norm(Xa - Xc)), float(np.linalg.norm(Xb - Xc))]
    # which painted end is the pipeline's A?
    ea = np.array(res["end_a_xyz"])
    ja = 0 if np.linalg.norm(ea - P[0]) < np.linalg.norm(ea - P[2]) else 2
    order = [ja, 2 - ja]
    summ["painted_legs_pipeline_order_m"] = [float(np.linalg.norm(P[order[0]] - C)), float(np.linalg.norm(P[order[1]] - C))]
    summ["end_err_m"] = [float(np.linalg.norm(np.array(res["end_a_xyz"]) - P[order[0]])),
                         float(np.linalg.norm(np.array(res["end_b_xyz"]) - P[order[1]]))]
    summ["corner_err_m"] = float(np.linalg.norm(np.array(res["corner_xyz"]) - C))

    def sfm_tri(ids, X):
        O, D = [], []
        for k in ids:
            uv = sfm_project(st, k, X)
            o, d = rp._world_rays(st.photos[k], uv, st.sim)
            O.append(o[0])
            D.append(d[0])
        return ls_point(np.array(O), np.array(D))

    Yc = sfm_tri(res["photo_ids_corner"], C)
    Ya, Yb = sfm_tri(res["photo_ids_a"], P[order[0]]), sfm_tri(res["photo_ids_b"], P[order[1]])
    summ["sfmcam_legs_m"] = [float(np.linalg.norm(Ya - Yc)), float(np.linalg.norm(Yb - Yc))]
    return summ, df


def fmt(x, n=3):
    return "–" if x is None else (f"{x:.{n}f}" if isinstance(x, float) else str(x))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--results", default="/work/wt/closerange9/results/kamech_twin")
    ap.add_argument("--scenes", nargs="*", default=SCENES)
    ap.add_argument("--method", default="current", help="label of the outputs; ending in 'rigid': re-rendered photos")
    ap.add_argument("--photos", default=None, help="re-rendered photos (folder with scene_NN/), else the stored ones")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "out"))
    ap.add_argument("--compare", action="store_true", help="only write closerange_rule_diagnosis.md from the two runs' JSON")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.compare:
        compare(out)
        return
    summs, dfs = [], []
    for sc in a.scenes:
        st = load_scene(Path(a.results), sc, REPO / "results" / "kamech_twin" / "closerange_rule",
                        photo_dir=Path(a.photos) / sc if a.photos else None)
        s, df = diagnose(st, a.method)
        print(s, flush=True)
        summs.append(s)
        dfs.append(df)
    views = pd.concat(dfs, ignore_index=True)
    views.to_csv(out / f"closerange_rule_diagnosis_{a.method}_views.csv", index=False, float_format="%.3f")
    pd.DataFrame(summs).to_json(out / f"closerange_rule_diagnosis_{a.method}.json", orient="records", indent=1)
    L = [f"# Folding-rule diagnosis ({a.method} code) on {a.results}", ""]
    L.append("| scene | stored scale % | scale % now | legs m (pipeline) | painted legs m (draped) | legs m, true cameras | legs m, SfM cameras on true points | end errors m | photos corner / A / B |")
    L.append("|---|---|---|---|---|---|---|---|---|")
    for s in summs:
        legs = lambda k: " / ".join(f"{x:.3f}" for x in s[k]) if k in s else "–"  # noqa: E731
        L.append(f"| {s['scene']} | {fmt(s['stored_scale_pct'], 2)} | {fmt(s.get('scale_pct'), 2)} | {legs('legs_m')} | "
                 f"{legs('painted_legs_pipeline_order_m')} | {legs('truecam_legs_m')} | {legs('sfmcam_legs_m')} | {legs('end_err_m')} | "
                 f"{s.get('n_corner', '–')} / {s.get('n_a', '–')} / {s.get('n_b', '–')} |")
    L += ["", "Per photo and end (rule views within 10 px of the true corner; along + = beyond the true end):", ""]
    L.append(views.to_markdown(index=False, floatfmt=".2f") if len(views) else "(none)")
    (out / f"closerange_rule_diagnosis_{a.method}.md").write_text("\n".join(L) + "\n")


def compare(out: Path, runs: tuple[str, ...] = ("baseline", "baseline_rigid", "new_rigid")) -> None:
    """``closerange_rule_diagnosis.md``: per scene, the stored photos (draped paint) next to the rigid rule's, old and new code."""
    R = [{s["scene"]: s for s in pd.read_json(out / f"closerange_rule_diagnosis_{m}.json").to_dict("records")} for m in runs]
    va = pd.read_csv(out / f"closerange_rule_diagnosis_{runs[0]}_views.csv")

    def legs(s, k):
        v = s.get(k)
        return "–" if not isinstance(v, list) else " / ".join(f"{x:.3f}" for x in v)

    def n(s):
        return "–" if not isinstance(s.get("n_corner"), (int, float)) or s.get("n_corner") != s.get("n_corner") else \
            f"{int(s['n_corner'])}/{int(s['n_a'])}/{int(s['n_b'])}"

    def pct(s):
        v = s.get("scale_pct")
        return "not found" if v is None or v != v else f"{v:.2f}"

    L = ["# Folding rule: where the scale error came from (issue 20; evaluation against the twin's truth)", "",
         "`benchmarks/closerange_rule_diagnosis.py` on the stored session-9 `make closerange` products (COLMAP model, sphere",
         "similarity re-derived as the stage does it, DEM), legs A / B in the pipeline's labels, metres:", "",
         f"* **{runs[0]}**: the stored photos (rule painted on the grass texture) and main's rule code;",
         "  *painted legs*: the 3-D distances corner → ends of the paint as the photos show it (plan position of the twin's",
         "  rule at the rendered surface's height); *true cameras*: the located corner/ends of the same photos triangulated",
         "  with the true poses (localisation error only); *SfM cameras on true points*: the true painted points projected",
         "  with the SfM cameras and triangulated (camera error only);",
         f"* **{runs[1]}**: the same photos with the rule's neighbourhood re-rendered as the rigid rule resting on the ground",
         "  (`benchmarks/closerange_rule_rerender.py`; legs exactly 1 m), main's rule code;",
         f"* **{runs[2]}**: those photos, this branch's rule code (gap bridged within a segment: a strip width + 2 px, was a",
         "  decimetre).", "",
         f"| scene | {runs[0]}: scale % | legs | painted legs | legs, true cameras | legs, SfM cameras on true points | "
         f"photos corner/A/B | {runs[1]}: scale % | legs | photos | {runs[2]}: scale % | legs | legs, true cameras | photos |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for sc in R[0]:
        a, b, c = R[0][sc], R[1].get(sc, {}), R[2].get(sc, {})
        L.append(f"| {sc} | {pct(a)} | {legs(a, 'legs_m')} | {legs(a, 'painted_legs_pipeline_order_m')} | {legs(a, 'truecam_legs_m')} | "
                 f"{legs(a, 'sfmcam_legs_m')} | {n(a)} | {pct(b)} | {legs(b, 'legs_m')} | {n(b)} | {pct(c)} | {legs(c, 'legs_m')} | "
                 f"{legs(c, 'truecam_legs_m')} | {n(c)} |")
    L += ["", f"{runs[0]}, per end over the rule's views (an L within 10 px of the true corner in the photo): the end located",
          "along its leg minus the painted end projected with the true camera (cm on the ground, + = beyond the end),",
          "across it (px); 'used' = the rays the pipeline grouped for that end.", "",
          "| scene | end | views | used | along cm, median of used | along cm, min / max of all | across px, median |",
          "|---|---|---|---|---|---|---|"]
    for sc, g in va.groupby("scene"):
        for e in ("A", "B"):
            used = g[g[f"{e}_used"]]
            L.append(f"| {sc} | {e} | {len(g)} | {len(used)} | {used[f'{e}_along_cm'].median():.1f} | "
                     f"{g[f'{e}_along_cm'].min():.1f} / {g[f'{e}_along_cm'].max():.1f} | {g[f'{e}_across_px'].median():.1f} |")
    (out / "closerange_rule_diagnosis.md").write_text("\n".join(L) + "\n")


if __name__ == "__main__":
    main()
