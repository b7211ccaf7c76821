"""Paper 004's georeferencing without RTK: taped triads, Horn on handheld GPS, tide datum.

Model coordinates of the targets and waterline points come from image clicks
triangulated with the joint SfM cameras (midpoint of rays, least squares). Then
``s = mean_k(d_tape / d_model)`` over the taped edges, Horn's quaternion rotation and
translation of the scaled targets onto their GPS positions (targets not in the bundle),
and a vertical shift that puts the mean of the waterline points at the tide height.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.dense.views import OrientedImage
from kitegully.georef.similarity import Similarity, horn_quaternion, tape_scale, umeyama


def read_tape(path: str | Path, targets: set[str]) -> list[tuple[str, str, float]]:
    """Taped edges ``(from, to, length_m)``; every target named must have a GPS position and
    every triad (connected group of edges) must be a closed triangle of 3 sides.

    Raises
    ------
    InputError
        One sentence naming the file and the missing target or the incomplete triad.
    """
    try:
        df = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the taped distances ({exc})") from None
    missing_cols = {"from", "to", "length_m"} - set(df.columns)
    if missing_cols:
        raise InputError(f"{path}: taped distances need the columns from, to, length_m (missing {', '.join(sorted(missing_cols))})")
    edges = [(str(a), str(b), float(d)) for a, b, d in zip(df["from"], df["to"], df["length_m"])]
    for a, b, d in edges:
        for t in (a, b):
            if t not in targets:
                raise InputError(f"{path}: taped edge {a}-{b} names target {t}, which has no GPS position")
        if not d > 0:
            raise InputError(f"{path}: taped edge {a}-{b} has a non-positive length {d}")
    # connected groups of the edge graph = triads
    group = {}
    for a, b, _ in edges:
        ga, gb = group.get(a, {a}), group.get(b, {b})
        merged = ga | gb
        for t in merged:
            group[t] = merged
    seen = []
    for g in group.values():
        if g in seen:
            continue
        seen.append(g)
        n_edges = sum(1 for a, b, _ in edges if a in g)
        if len(g) != 3 or n_edges != 3:
            raise InputError(f"{path}: the triad of targets {', '.join(sorted(g))} has {n_edges} taped side(s); "
                             "a triad needs its 3 sides taped")
    return edges


def read_points(path: str | Path, what: str) -> dict[str, np.ndarray]:
    """Target coordinates ``target, x_m, y_m, z_m`` as a dict."""
    df = pd.read_csv(path)
    need = {"target", "x_m", "y_m", "z_m"}
    if not need <= set(df.columns):
        raise InputError(f"{path}: {what} need the columns target, x_m, y_m, z_m")
    return {str(r.target): np.array([r.x_m, r.y_m, r.z_m], float) for r in df.itertuples()}


def ray(img: OrientedImage, u: float, v: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre and unit direction (model frame) of the ray through pixel ``(u, v)``
    (COLMAP pixel convention), undistorting the RADIAL model by fixed-point iteration.

    Parameters
    ----------
    img : OrientedImage
        Registered image: pose, focal length and principal point (px), radial terms ``k1, k2``.
    u, v : float
        Pixel column and row (px).

    Returns
    -------
    centre : ndarray (3,)
        Projection centre of the image (model frame).
    direction : ndarray (3,)
        Unit direction of the ray (model frame).
    """
    xd, yd = (u - img.cx) / img.f, (v - img.cy) / img.f
    x, y = xd, yd
    for _ in range(20):
        r2 = x * x + y * y
        d = 1 + img.k1 * r2 + img.k2 * r2 * r2
        x, y = xd / d, yd / d
    dirn = img.R.T @ np.array([x, y, 1.0])
    return img.C, dirn / np.linalg.norm(dirn)


def triangulate(clicks: pd.DataFrame, images: Mapping[str, OrientedImage], min_views: int = 2) -> dict[str, np.ndarray]:
    """Least-squares intersection of the rays of each clicked point (columns ``image, point,
    u_px, v_px``); points seen in fewer than ``min_views`` registered images are dropped.
    O(clicks).

    Parameters
    ----------
    clicks : DataFrame
        One row per click: image name, point id and pixel position ``u_px, v_px`` (px).
    images : mapping
        Registered images (:class:`OrientedImage`) by name; clicks on other images are skipped.
    min_views : int
        Fewest registered images a point needs to be kept.

    Returns
    -------
    dict
        Model coordinates (ndarray (3,)) of each kept point, keyed by point id as a string.
    """
    out = {}
    for pid, grp in clicks.groupby("point"):
        A, b, n = np.zeros((3, 3)), np.zeros(3), 0
        for r in grp.itertuples():
            img = images.get(r.image)
            if img is None:
                continue
            C, d = ray(img, r.u_px, r.v_px)
            M = np.eye(3) - np.outer(d, d)
            A += M
            b += M @ C
            n += 1
        if n >= min_views:
            out[str(pid)] = np.linalg.solve(A, b)
    return out


def georeference_tape_horn(model_t: Mapping[str, np.ndarray], gps: Mapping[str, np.ndarray],
                           edges: list[tuple[str, str, float]], model_water: np.ndarray, water_level_m: float,
                           level: bool = False, min_spread_m: float = 1.0) -> tuple[Similarity, float, pd.DataFrame]:
    """Tape scale, Horn on GPS, tide shift (and with ``level`` the waterline levelled first,
    :func:`level_to_water`). Returns the similarity (shift included in its translation),
    the shift (m) and the residual table of Horn's fit (global, local, per target/edge).

    Parameters
    ----------
    model_t : mapping
        Triangulated target coordinates (ndarray (3,), model frame) by target name.
    gps : mapping
        Handheld GPS positions of the targets (ndarray (3,), m) by target name.
    edges : list of (str, str, float)
        Taped edges ``(from, to, length_m)`` as :func:`read_tape` gives them.
    model_water : ndarray (n, 3)
        Triangulated waterline points (model frame).
    water_level_m : float
        Tide height of the water surface (m).
    level : bool
        Level the waterline with :func:`level_to_water` before the shift.
    min_spread_m : float
        Across spread (SD, m) the waterline needs for its across slope to be levelled.

    Returns
    -------
    sim : Similarity
        Model to GPS frame, tide shift included in the translation.
    shift : float
        Vertical shift (m) that puts the mean waterline at ``water_level_m``.
    residuals : DataFrame
        :func:`residual_rows` of Horn's fit, before levelling and shift.
    """
    s, ratios = tape_scale(dict(model_t), edges)
    ids = [k for k in model_t if k in gps]
    if len(ids) < 3:
        raise InputError(f"Horn's method needs at least 3 triangulated targets with GPS positions, got {len(ids)}")
    a = np.array([model_t[k] for k in ids]) * s
    b = np.array([gps[k] for k in ids])
    rigid = horn_quaternion(a, b)
    sim = Similarity(s, rigid.R, rigid.t)
    res = np.linalg.norm(sim.apply(np.array([model_t[k] for k in ids])) - b, axis=1)
    if len(model_water) == 0:
        raise InputError("no waterline point was triangulated; the vertical datum cannot be set")
    if level:
        sim = level_to_water(sim, model_water, min_spread_m)
    dz = water_level_m - float(np.mean(sim.apply(model_water)[:, 2]))
    final = Similarity(s, sim.R, sim.t + np.array([0.0, 0.0, dz]))
    return final, dz, residual_rows("tape_horn_gps", Similarity(s, rigid.R, rigid.t), model_t, ids, edges, res)


def level_to_water(sim: Similarity, model_water: np.ndarray, min_spread_m: float) -> Similarity:
    """Turn the georeferenced model so that the waterline is level ([I] the water surface is
    a level surface of known height: besides the paper's shift it fixes the tilt that GPS
    heights (±2 m over a few tens of metres) leave in Horn's rotation).

    A plane ``z = a·u + b·v + c`` is fitted to the waterline points on their principal
    horizontal axes ``u`` (along) and ``v`` (across); the across slope ``b`` is kept only
    when the points spread at least ``min_spread_m`` (SD) across, else it is unobserved
    and left as Horn gave it. The model is then rotated about the points' centroid so the
    fitted plane becomes horizontal. O(points).

    Parameters
    ----------
    sim : Similarity
        Model to site similarity from Horn's fit.
    model_water : ndarray (n, 3)
        Waterline points (model frame).
    min_spread_m : float
        Least across spread (SD, m) for the across slope to be fitted.

    Returns
    -------
    Similarity
        The levelled similarity; ``sim`` itself with fewer than 3 points or a plane already level.
    """
    W = sim.apply(model_water)
    if len(W) < 3:
        return sim
    c = W.mean(axis=0)
    d = W - c
    _, sv, vt = np.linalg.svd(d[:, :2], full_matrices=False)
    e_u, e_v = vt[0], vt[1]
    u, v = d[:, :2] @ e_u, d[:, :2] @ e_v
    spread_v = float(sv[1] / np.sqrt(len(W)))
    if spread_v >= min_spread_m:
        (a, b, _), *_ = np.linalg.lstsq(np.column_stack([u, v, np.ones_like(u)]), d[:, 2], rcond=None)
    else:
        (a, _), *_ = np.linalg.lstsq(np.column_stack([u, np.ones_like(u)]), d[:, 2], rcond=None)
        b = 0.0
    g = a * e_u + b * e_v                                   # gradient dz/dx, dz/dy
    n = np.array([-g[0], -g[1], 1.0])
    n /= np.linalg.norm(n)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(n, z)
    sin, cos = np.linalg.norm(axis), float(n @ z)
    if sin < 1e-12:
        return sim
    k = axis / sin
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    Rt = np.eye(3) + sin * K + (1 - cos) * K @ K             # Rodrigues: n -> z
    return Similarity(sim.scale, Rt @ sim.R, Rt @ (sim.t - c) + c)


def georeference_rtk(model_t: Mapping[str, np.ndarray], rtk: Mapping[str, np.ndarray],
                     edges: list[tuple[str, str, float]]) -> tuple[Similarity, pd.DataFrame]:
    """Comparison block: 7-parameter similarity (scale from the coordinates) on RTK-grade
    target coordinates.

    Parameters
    ----------
    model_t : mapping
        Triangulated target coordinates (ndarray (3,), model frame) by target name.
    rtk : mapping
        RTK-grade target coordinates (ndarray (3,), m) by target name.
    edges : list of (str, str, float)
        Taped edges ``(from, to, length_m)``; used only for the edge rows of the residual table.

    Returns
    -------
    sim : Similarity
        Model to RTK frame, fitted on the targets in both mappings.
    residuals : DataFrame
        :func:`residual_rows` of the fit.
    """
    ids = [k for k in model_t if k in rtk]
    a = np.array([model_t[k] for k in ids])
    b = np.array([rtk[k] for k in ids])
    sim = umeyama(a, b)
    res = np.linalg.norm(sim.apply(a) - b, axis=1)
    return sim, residual_rows("similarity_rtk", sim, model_t, ids, edges, res)


def residual_rows(method: str, sim: Similarity, model_t: Mapping[str, np.ndarray], ids: list[str],
                  edges: list[tuple[str, str, float]], res: np.ndarray) -> pd.DataFrame:
    """Residual table rows: global mean 3-D, local mean edge-length, each target and edge.

    Parameters
    ----------
    method : str
        Method label of every row; a label starting with ``tape`` gets the paper's values in ``paper_m``.
    sim : Similarity
        Fitted similarity; only its scale is used, for the edge lengths.
    model_t : mapping
        Target coordinates (ndarray (3,), model frame) by target name.
    ids : list of str
        Targets of the fit, in the order of ``res``.
    edges : list of (str, str, float)
        Taped edges ``(from, to, length_m)``; those with both targets in ``model_t`` give edge rows.
    res : ndarray (n,)
        3-D residual (m) of each target in ``ids``.

    Returns
    -------
    DataFrame
        Columns ``method, scope, item, residual_m, paper_m``; an edge residual is the scaled
        model length minus the tape (m).
    """
    edge_res = []
    for a, b, d in edges:
        if a in model_t and b in model_t:
            edge_res.append((f"{a}-{b}", sim.scale * float(np.linalg.norm(model_t[a] - model_t[b])) - d))
    rows = [{"method": method, "scope": "global", "item": "mean 3-D target residual", "residual_m": float(np.mean(res)),
             "paper_m": 1.016 if method.startswith("tape") else np.nan},
            {"method": method, "scope": "local", "item": "mean |edge length - tape|",
             "residual_m": float(np.mean([abs(r) for _, r in edge_res])), "paper_m": 0.039 if method.startswith("tape") else np.nan}]
    rows += [{"method": method, "scope": "target", "item": k, "residual_m": float(r), "paper_m": np.nan} for k, r in zip(ids, res)]
    rows += [{"method": method, "scope": "edge", "item": k, "residual_m": float(r), "paper_m": np.nan} for k, r in edge_res]
    return pd.DataFrame(rows)
