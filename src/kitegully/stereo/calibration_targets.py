"""The control field's targets as printed discs, rendered into calibration photographs and measured there.

Each target is a white disc on a black plate (:func:`calibration_targets`); :func:`render_calibration_image`
renders them through a camera and pose, and :func:`measure_targets` locates each disc (template search and a
weighted centroid, corrected for the projected disc's offset, :func:`projected_disc_offset_px`), giving the
:class:`~kitegully.stereo.control_field.Observation` that :mod:`kitegully.stereo.calibration` adjusts.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kitegully import InputError
from kitegully.stereo.control_field import ControlField, Observation
from kitegully.twin.camera import Camera, Pose

if TYPE_CHECKING:
    from kitegully.stereo.measure import PrintedMarks

log = logging.getLogger(__name__)

#: Target disc diameter (m). [I] 10 mm, the frame marks' print (:class:`kitegully.stereo.measure.MarkDesign`):
#: the ground pixel is 3.0 m · 0.0094 / 51.4 = 0.55 mm under the nadir stations and at most
#: 3.6 m · 0.0094 / 51.4 = 0.66 mm at the far side of the field from a convergent station, so a disc is
#: 15–18 px across: every pixel of it enters the centroid (close-range practice asks ≥ 5–10 px), and its
#: 24 mm black plate (≤ 44 px) stays far inside the 0.10–0.15 m spacing of the targets.
TARGET_DIAMETER_M = 0.010


def calibration_targets(field: ControlField, diameter_m: float = TARGET_DIAMETER_M) -> PrintedMarks:
    """The field's targets as printed discs: a white disc on a black square plate, horizontal, centred on each target.

    Pole tops carry the plate on the pole (the pole itself is not rendered: under the plate it is hidden
    from the nadir stations, and from the 27° convergent stations its side appears beyond the plate's
    edge, outside the centroid's background annulus of radius 2r < the plate's half side 2.4r·cos 27°).
    """
    from kitegully.stereo.measure import MarkDesign, PrintedMarks

    return PrintedMarks(np.asarray(field.xyz, float), MarkDesign(diameter_m))


def render_calibration_image(camera: Camera, pose: Pose, targets: PrintedMarks, noise_dn: float,
                             rng: np.random.Generator, window: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """One calibration photograph: the printed targets over a plain grey table (reflectance 0.30), 0–255 float.

    [I] The table's texture is irrelevant to a target: each disc is measured against its own black plate.
    The table top is 1 mm below the table targets' print (a card on the table), so the ray hits the plate first.
    Cost: O(pixels · targets) for the exact ray–plate intersections (:meth:`PrintedMarks.intersect`).

    Parameters
    ----------
    camera, pose : Camera, Pose
        Inner and exterior orientation of the station.
    targets : PrintedMarks
        The printed targets (:func:`calibration_targets`).
    noise_dn : float
        Standard deviation of the Gaussian image noise (digital numbers).
    rng : Generator
        Noise generator.
    window : (x0, y0, x1, y1) or None
        Render only this pixel window (end exclusive); the rest of the frame is NaN. ``None`` renders the whole frame.

    Returns
    -------
    ndarray (height, width) float32
        The photograph, 0–255 plus noise; NaN outside ``window``.
    """
    from kitegully.stereo.synth import Texture, render_heightfield

    table = Texture(np.full((400, 400), 0.30, np.float32), -2.0, 2.0, 0.01)
    return render_heightfield(camera, pose, lambda x, y: np.full_like(x, -1e-3), table, z_start=-1e-3, noise_dn=noise_dn, rng=rng,
                              window=window, marks=targets)


def projected_disc_offset_px(camera: Camera, pose: Pose, xyz: np.ndarray, radius_m: float, n: int = 720) -> np.ndarray:
    """Offset (N × 2, px) of the area centroid of each imaged disc from the image of its centre.

    A circle's perspective image is an ellipse whose centre is not the image of the circle's
    centre: to first order the shift is f·r²·sin θ·cos θ / Z² (θ the plate's tilt to the image
    plane, Z its distance), plus the (smaller) share of the lens distortion's curvature across the
    disc. Computed exactly here: the disc's rim (``n`` points, horizontal plate) is projected
    through ``camera`` (distortion included) and the centroid of the polygon it bounds taken
    (shoelace formula). O(N · n).

    Parameters
    ----------
    camera, pose : Camera, Pose
        Inner and exterior orientation.
    xyz : ndarray (N, 3)
        Disc centres, world coordinates (m).
    radius_m : float
        Disc radius (m).
    n : int
        Number of rim points per disc.

    Returns
    -------
    ndarray (N, 2)
        Centroid of each imaged disc minus the image of its centre (px).
    """
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    X = np.asarray(xyz, float)
    rim = X[:, None, :] + radius_m * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)[None]
    uv = camera.project(rim.reshape(-1, 3), pose).reshape(len(X), n, 2)
    x, y = uv[..., 0], uv[..., 1]
    x1, y1 = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cr = x * y1 - x1 * y
    A = 0.5 * cr.sum(axis=1)
    cx = ((x + x1) * cr).sum(axis=1) / (6 * A)
    cy = ((y + y1) * cr).sum(axis=1) / (6 * A)
    return np.column_stack([cx, cy]) - camera.project(X, pose)


@dataclass(frozen=True)
class TargetMeasurement:
    """Targets located in one calibration photograph: the observation, each centroid's σ from the image noise (px), and the ids dropped at the frame edge."""

    observation: Observation
    sigma_px: np.ndarray
    dropped: tuple[str, ...]


def measure_targets(image: np.ndarray, predict_camera: Camera, pose: Pose, field: ControlField, diameter_m: float,
                    allowance_px: float, name: str) -> TargetMeasurement:
    """Locate every calibration target in one photograph (template + iterated weighted centroid of :mod:`kitegully.stereo.measure`).

    Parameters
    ----------
    image : ndarray (H, W)
        Photograph, 0–255 (NaN = not rendered).
    predict_camera : Camera
        Camera used to predict where each target is (the nominal lens: its f, principal point and
        distortion are what the calibration is to find, so the prediction is off by up to ``allowance_px``).
    pose : Pose
        The station as set up (planned position, tilts and swing).
    field : ControlField
        Target ids and stated coordinates.
    diameter_m : float
        Printed disc diameter (m).
    allowance_px : float
        Bound on the prediction error (px). A target predicted within ``allowance_px`` plus its
        measuring window of the frame's edge that is not found (window leaving the frame, or disc cut
        off) is dropped with a log line (legitimately at the edge of the frame); a target predicted outside the frame by more
        than its window is not looked for.
    name : str
        Image name for messages.

    Returns
    -------
    TargetMeasurement

    Raises
    ------
    InputError
        A target predicted well inside the frame that is not found (window outside the rendered
        part, or disc contrast below 5 σ of the plate's noise): one sentence naming the image and target.

    Notes
    -----
    Search gate: half the smallest predicted spacing of two targets in this image (never reaches a
    neighbour's disc), at most ``2·allowance_px``. Cost: O(targets · gate²), a few ms per target.
    """
    from kitegully.stereo.measure import MARK_DETECTION_SIGMA, predict_marks, search_disc

    P, R = predict_marks(predict_camera, pose, field.xyz, diameter_m)
    img = np.asarray(image, np.float32)
    h, w = img.shape
    edge = np.minimum.reduce([P[:, 0], P[:, 1], w - 1 - P[:, 0], h - 1 - P[:, 1]])  # distance inside the frame (px, < 0 outside)
    need = 2.0 * R + 2.0  # the centroid's background annulus reaches 2r (+ rounding)
    look = edge > -need
    # [I] a target another plate reaches into (its measuring window of radius 2r + 2 overlaps the other plate,
    # half-diagonal 1.2·√2·D): the convergent stations see a 0.3 m pole top over a table target. Predicted from
    # the stated field and the planned station; such a target is not measured in that image (logged).
    dd = np.linalg.norm(P[:, None] - P[None], axis=2)
    dd[np.diag_indices(len(dd))] = np.inf
    crowded = look & ((dd - need[:, None] - 1.2 * np.sqrt(2) * 2 * R[None, :]) < 0).any(axis=1)
    if crowded.any():
        log.info("%s: target(s) %s not measured: another target's plate reaches into the measuring window", name,
                 ", ".join(field.ids[crowded].tolist()))
    look &= ~crowded
    dd = dd[np.ix_(look, look)]
    gate = min(0.5 * float(dd.min()) if len(dd) > 1 else np.inf, 2.0 * allowance_px)
    ids, uv, sig, dropped = [], [], [], []
    for i in np.flatnonzero(~look):
        dropped.append(str(field.ids[i]))
    for i in np.flatnonzero(look):
        p, r = P[i], float(R[i])
        found = search_disc(img, p, r, gate)
        weak = found is None or not found[2] > MARK_DETECTION_SIGMA * max(found[3], 1e-6)
        if weak and edge[i] < allowance_px + need[i]:  # at the frame's edge: cut off or outside, legitimately
            dropped.append(str(field.ids[i]))
            continue
        if found is None or not found[2] > MARK_DETECTION_SIGMA * max(found[3], 1e-6):
            why = ("its measuring window leaves the rendered image" if found is None else
                   f"the brightest disc there has a contrast of {found[2]:.1f} DN against {found[3]:.1f} DN of noise, below {MARK_DETECTION_SIGMA:g} σ")
            raise InputError(f"{name}: calibration target {field.ids[i]} not found within {gate:.0f} px of its predicted position "
                             f"({p[0]:.0f}, {p[1]:.0f}): {why}")
        ids.append(field.ids[i])
        uv.append(found[0])
        sig.append(found[1])
    if dropped:
        log.info("%s: %d target(s) at or beyond the frame's edge not measured: %s", name, len(dropped), ", ".join(dropped))
    return TargetMeasurement(Observation(np.array(ids), np.array(uv, float).reshape(-1, 2)), np.array(sig), tuple(dropped))


def measure_calibration_images(camera: Camera, predict_camera: Camera, field_true: ControlField, stated: ControlField,
                               poses: list[Pose], diameter_m: float, noise_dn: float, rng: np.random.Generator,
                               allowance_px: float, name: str) -> tuple[list[Observation], float]:
    """Twin step + measurement: render each calibration photograph (targets at their true places) and locate the targets.

    Only the part of each frame around a target is rendered (a 241 px window per target, the plates within
    200 px of it): identical pixels there, a fraction of a full frame's cost. Returns the observations and the
    median centroid σ from the image noise (px). Cost: ≈ 0.4 s CPU per image.

    Parameters
    ----------
    camera : Camera
        The true camera the photographs are rendered with.
    predict_camera : Camera
        Camera used to predict where each target is (the nominal lens); it also places the render windows.
    field_true : ControlField
        Targets at their true places (m), as rendered.
    stated : ControlField
        Targets at their stated coordinates (m), as measured against.
    poses : list[Pose]
        One station per photograph.
    diameter_m : float
        Printed disc diameter (m).
    noise_dn : float
        Standard deviation of the Gaussian image noise (digital numbers).
    rng : Generator
        Noise generator.
    allowance_px : float
        Bound on the prediction error (px), as in :func:`measure_targets`.
    name : str
        Camera name for messages; each image is named ``"{name} image {k}"``, k counted from 1.

    Returns
    -------
    observations : list[Observation]
        Targets located in each photograph, one per pose.
    sigma_px : float
        Median centroid σ from the image noise over all targets (px).
    """
    obs, sig = [], []
    for k, pose in enumerate(poses):
        P = predict_camera.project(field_true.xyz, pose)
        img = np.full((camera.height, camera.width), np.nan, np.float32)
        for p in P:
            if not (-60 < p[0] < camera.width + 60 and -60 < p[1] < camera.height + 60):
                continue
            near = np.linalg.norm(P - p, axis=1) < 200
            win = (int(p[0]) - 120, int(p[1]) - 120, int(p[0]) + 121, int(p[1]) + 121)
            sub = render_calibration_image(camera, pose, calibration_targets(ControlField(field_true.ids[near], field_true.xyz[near]), diameter_m),
                                           noise_dn, rng, win)
            x0, y0, x1, y1 = max(0, win[0]), max(0, win[1]), min(camera.width, win[2]), min(camera.height, win[3])
            img[y0:y1, x0:x1] = sub[y0:y1, x0:x1]
        m = measure_targets(img, predict_camera, pose, stated, diameter_m, allowance_px, f"{name} image {k + 1}")
        obs.append(m.observation)
        sig.append(m.sigma_px)
    return obs, float(np.median(np.concatenate(sig)))
