"""A twin of paper 004's low-cost kite survey: a rocky shore strip, two kite flights (RGB
and NIR-converted camera), taped checkerboard triads, handheld-GPS positions and a tide level.

The strip runs east along ``x``; the ground rises northwards from the sea, whose surface
is the tide height above datum. Cover classes (water, wet rock, rock, algae, plants) carry
B, G, R and NIR reflectance anchors; the texture holds the four bands per 1 cm cell. A
camera channel integrates the spectrum (anchors linearly interpolated in wavelength)
under daylight times its spectral response: ``c = Σ_b W_cb ρ_b`` with
``W_cb = Σ_λ E(λ) S_c(λ) φ_b(λ) Δλ`` (``φ_b`` the hat function of anchor ``b``). The RGB
camera's response is the colour-science D5100 set, the NIR-converted camera's is
:func:`~kitegully.lowcost.spectral.nir_converted_response` (NIR in every channel; the
survey reads the red one only, as the paper).

Observed outputs (what a field team has): the photographs (JPEG with EXIF; each camera
its own make/model), image clicks of the 9 targets and of points along the waterline,
handheld-GPS and RTK target coordinates, the taped edge lengths, the tide height and a
Spectralon panel shot per camera. Truth: surface, cover classes, class spectra and NDVI,
target positions, camera poses.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import pandas as pd
from scipy import ndimage
from skimage import measure

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import GridSpec, Raster
from kitegully.io.tables import write_table
from kitegully.lowcost import spectral as sp
from kitegully.seeds import rng_for
from kitegully.twin.camera import Camera, Pose, nadir_rotation
from kitegully.twin.exif import exif_bytes, write_jpeg
from kitegully.twin.render import Photographic, make_scene, photograph, render_reflectance, surface_height, visible

if TYPE_CHECKING:
    from kitegully.twin.render import Scene

log = logging.getLogger(__name__)

#: Wavelength (nm) of each reflectance anchor of the twin's texture bands (B, G, R, NIR). [I]
ANCHORS_NM = {"B": 470.0, "G": 540.0, "R": 660.0, "NIR": 740.0}
BANDS = ("R", "G", "B", "NIR")          # texture band order (the renderer's convention)
CLASS_CODES = {"water": 1, "wet_rock": 2, "rock": 3, "algae": 4, "plants": 5}


@dataclass(frozen=True)
class LowcostTwinParams:
    """The ``lowcost.twin`` section: strip, cover, targets, flights and field measurements.

    Attributes
    ----------
    origin_xy : tuple
        South-west corner of the strip in the site CRS (m).
    length_m, width_m : float
        Strip size along x (east) and y (north) [I] 40 x 14 m, a part of the paper's
        200 x 30 m shore that keeps the run within 10 minutes.
    dsm_cell_m, texture_cell_m : float
        Surface and texture cells (m); the texture is about half the photo pixel.
    tide_m : float
        Water level above datum at capture [P] 0.16 m.
    waterline_y_m : float
        Mean distance of the waterline from the southern edge (m).
    shore_slope : float
        Rise per metre northwards [I].
    relief_m, relief_scale_m : float
        Amplitude and horizontal scale of rock relief [I].
    wet_band_m : float
        Height above the tide that stays wet [I].
    classes : dict
        Class name -> {B, G, R, NIR} reflectance anchors [I].
    target_side_m, target_panel_m : float
        Triad side [P] 2 m and checkerboard panel size [P] 0.2 m.
    gps_sd_xy_m, gps_sd_z_m : float
        Handheld GPS error SD per axis [P] ±2 m read as ≈ 2 SD horizontal: 1 m; vertical 2 m [I].
    rtk_sd_m : float
        RTK-grade survey SD for the comparison block [I] 0.015 m.
    tape_sd_m : float
        Tape reading SD [I] 5 mm.
    click_sd_px, waterline_click_sd_px : float
        Image measurement SD of target centres and of the traced waterline [I].
    waterline_points : int
        Points clicked along the waterline.
    camera : dict
        Sensor size, focal length, image size (px) of both cameras.
    flight : dict
        Height range, lines, spacing and kite jitter of each flight.
    photographic : dict
        :class:`~kitegully.twin.render.Photographic` keys.
    panel_reflectance : float
        Reflectance of the white-balance panel (Spectralon) [I] 0.99.
    """

    origin_xy: tuple[float, float]
    length_m: float
    width_m: float
    dsm_cell_m: float
    texture_cell_m: float
    tide_m: float
    waterline_y_m: float
    shore_slope: float
    relief_m: float
    relief_scale_m: float
    wet_band_m: float
    classes: dict
    target_side_m: float
    target_panel_m: float
    gps_sd_xy_m: float
    gps_sd_z_m: float
    rtk_sd_m: float
    tape_sd_m: float
    click_sd_px: float
    waterline_click_sd_px: float
    waterline_points: int
    camera: dict
    flight: dict
    photographic: dict
    panel_reflectance: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "LowcostTwinParams":
        """Build from ``lowcost.twin``; raises InputError naming a bad key."""
        config_section(cfg, "lowcost.twin", cls.__dataclass_fields__)
        for name in CLASS_CODES:
            if name not in cfg["classes"]:
                raise InputError(f"lowcost.twin.classes: cover class {name!r} is missing")
        for k in ("length_m", "width_m", "dsm_cell_m", "texture_cell_m", "target_side_m"):
            if not float(cfg[k]) > 0:
                raise InputError(f"lowcost.twin.{k}: must be positive, got {cfg[k]!r}")
        vals = dict(cfg)
        vals["origin_xy"] = tuple(float(v) for v in cfg["origin_xy"])
        return cls(**vals)


# --------------------------------------------------------------------------- spectra


def band_weights(response: np.ndarray, wavelengths: np.ndarray, light: np.ndarray) -> np.ndarray:
    """``W`` (channels, 4 bands in texture order R, G, B, NIR): channel value of unit
    reflectance in one anchor band, the spectrum linearly interpolated between anchors and
    held flat beyond them.

    Parameters
    ----------
    response : ndarray (n_wl, channels) or (n_wl,)
        Spectral response of each camera channel.
    wavelengths : ndarray (n_wl,)
        Wavelength grid (nm).
    light : ndarray (n_wl,)
        Relative spectral power of the illuminant.

    Returns
    -------
    ndarray (channels, 4)
        Band weights ``W``, columns in texture order R, G, B, NIR.
    """
    order = ["B", "G", "R", "NIR"]
    xs = np.array([ANCHORS_NM[b] for b in order])
    R = np.atleast_2d(np.asarray(response, float).T).T if np.ndim(response) == 1 else np.asarray(response, float)
    W = np.zeros((R.shape[1], 4))
    for j, b in enumerate(order):
        hat = np.interp(wavelengths, xs, np.eye(4)[j])
        W[:, BANDS.index(b)] = (light * hat) @ R
    return W


def camera_weights(wavelengths: np.ndarray, light: np.ndarray) -> dict[str, np.ndarray]:
    """Band weights of the RGB camera (R, G, B) and the NIR-converted camera ([I] its green
    and blue channels see NIR at 0.85 and 0.8 of the red channel, the dyes being
    transparent there)."""
    rgb = band_weights(sp.rgb_response(wavelengths), wavelengths, light)
    nir_r = band_weights(sp.nir_converted_response(wavelengths), wavelengths, light)[0]
    return {"rgb": rgb, "nir": np.vstack([nir_r, 0.85 * nir_r, 0.8 * nir_r])}


def class_table(classes: Mapping[str, Mapping[str, float]], weights: Mapping[str, np.ndarray]) -> pd.DataFrame:
    """Per class: anchors, band NDVI ``(NIR−R)/(NIR+R)`` and the camera NDVI the paper
    predicts, ``(N−r)/(N+r)`` of the white-balanced red channels (``Σ_b W_b ρ_b / Σ_b W_b``)."""
    rows = []
    for name, code in CLASS_CODES.items():
        c = classes[name]
        rho = np.array([c["R"], c["G"], c["B"], c["NIR"]], float)
        red = weights["rgb"][0] @ rho / weights["rgb"][0].sum()
        nir = weights["nir"][0] @ rho / weights["nir"][0].sum()
        rows.append({"class": name, "code": code, "B": c["B"], "G": c["G"], "R": c["R"], "NIR": c["NIR"],
                     "ndvi_band": (c["NIR"] - c["R"]) / (c["NIR"] + c["R"]), "ndvi_camera": (nir - red) / (nir + red)})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- ground


def _noise(rng: np.random.Generator, shape: tuple[int, int], sigma_cells: float) -> np.ndarray:
    """Gaussian-filtered white noise scaled to zero mean and unit SD (float64). Filtered and
    scaled in place (8 bytes per cell; the same values as filtering into a new array)."""
    n = rng.standard_normal(shape)
    ndimage.gaussian_filter(n, sigma_cells, mode="wrap", output=n)
    m, s = n.mean(), max(n.std(), 1e-12)
    n -= m
    n /= s
    return n


def make_ground(p: LowcostTwinParams, seed: int) -> tuple[GridSpec, np.ndarray, np.ndarray, np.ndarray]:
    """Terrain, surface (terrain or water at the tide) and cover class on the DSM grid.
    O(cells)."""
    c = p.dsm_cell_m
    grid = GridSpec(p.origin_xy[0], p.origin_xy[1] + p.width_m, c, int(round(p.length_m / c)), int(round(p.width_m / c)), "")
    h, w = grid.shape
    rng = rng_for(seed, "lowcost", "ground")
    y = (p.width_m - (np.arange(h) + 0.5) * c)[:, None] * np.ones((1, w))
    relief = _noise(rng, (h, w), p.relief_scale_m / c) * p.relief_m + _noise(rng, (h, w), 0.3 / c) * 0.03
    terrain = p.tide_m + p.shore_slope * (y - p.waterline_y_m) + relief
    surface = np.maximum(terrain, p.tide_m)
    n1, n2 = _noise(rng, (h, w), 1.2 / c), _noise(rng, (h, w), 0.8 / c)
    above = terrain - p.tide_m
    cls = np.full((h, w), CLASS_CODES["rock"], np.uint8)
    cls[above < p.wet_band_m] = CLASS_CODES["wet_rock"]
    cls[(above < 4 * p.wet_band_m) & (n2 > 0.5)] = CLASS_CODES["algae"]
    n3 = _noise(rng, (h, w), 2.0 / c)
    cls[(y + 1.5 * n3 > 0.6 * p.width_m) & (n1 > 0.3)] = CLASS_CODES["plants"]
    cls[terrain < p.tide_m] = CLASS_CODES["water"]
    return grid, terrain.astype(np.float32), surface.astype(np.float32), cls


def target_layout(p: LowcostTwinParams, seed: int) -> dict[str, np.ndarray]:
    """Horizontal positions of the 9 targets: 3 equilateral triads of ``target_side_m`` along
    the strip, each turned at random. Names ``T<triad><vertex>``."""
    rng = rng_for(seed, "lowcost", "targets")
    out = {}
    r = p.target_side_m / np.sqrt(3.0)
    for i, fx in enumerate((0.2, 0.5, 0.8)):
        cx, cy = p.origin_xy[0] + fx * p.length_m, p.origin_xy[1] + 0.62 * p.width_m
        a0 = rng.uniform(0, 2 * np.pi)
        for j in range(3):
            a = a0 + j * 2 * np.pi / 3
            out[f"T{i + 1}{'abc'[j]}"] = np.array([cx + r * np.cos(a), cy + r * np.sin(a)])
    return out


def make_texture(p: LowcostTwinParams, grid: GridSpec, cls: np.ndarray, targets: Mapping[str, np.ndarray],
                 seed: int, chunk_rows: int = 1024) -> tuple[np.ndarray, float]:
    """(4, rows, cols) uint8 reflectance x 255 in band order R, G, B, NIR, on a grid
    ``texture_cell_m`` fine; class anchors times a multi-scale brightness texture (so
    SIFT finds features), checkerboard targets painted on.

    O(texture cells) time. Memory, N texture cells: 4 N bytes out, and at the peak about
    26 N (three float64 noise fields generated one after the other, each filtered and
    scaled in place, summed into one float64 brightness field); the bands are quantised
    ``chunk_rows`` rows at a time (the result does not depend on it). 2.3 GB at the
    5 mm site's 2.5 mm texture over 40 x 14 m (N = 89.6 M).

    Parameters
    ----------
    p : LowcostTwinParams
        The twin's parameters (texture cell, class anchors, target panel size).
    grid : GridSpec
        DSM grid; the texture cell is its cell divided by a whole number.
    cls : ndarray (H, W) uint8
        Cover class codes on ``grid``.
    targets : mapping
        Horizontal target positions (ndarray (2,), m) by name.
    seed : int
        The run's seed (texture stream ``rng_for(seed, "lowcost", "texture")``).
    chunk_rows : int
        Texture rows quantised at a time.

    Returns
    -------
    texture : ndarray (4, rows, cols) uint8
        Reflectance x 255 in band order R, G, B, NIR.
    cell : float
        Texture cell size (m).
    """
    k = max(1, int(round(grid.cell / p.texture_cell_m)))
    tc = grid.cell / k
    big = np.repeat(np.repeat(cls, k, axis=0), k, axis=1)
    rng = rng_for(seed, "lowcost", "texture")
    shape = big.shape
    # exp(0.25 n(1.5) + 0.2 n(6) + 0.15 n(25)), summed left to right in place
    bright = _noise(rng, shape, 1.5)
    bright *= 0.25
    for weight, sigma in ((0.2, 6.0), (0.15, 25.0)):
        n = _noise(rng, shape, sigma)
        n *= weight
        bright += n
        del n
    np.exp(bright, out=bright)
    water = big == CLASS_CODES["water"]
    ripples = _noise(rng, shape, 3.0)                                   # ripples: little contrast
    ripples *= 0.08
    np.exp(ripples, out=ripples)
    bright[water] = ripples[water]
    del ripples, water
    lut = np.zeros((len(BANDS), int(big.max()) + 1), np.float32)        # class code -> anchor, per band
    for name, code in CLASS_CODES.items():
        for b, band in enumerate(BANDS):
            lut[b, code] = p.classes[name][band]
    out = np.empty((len(BANDS),) + shape, np.uint8)
    for r0 in range(0, shape[0], chunk_rows):
        rows = slice(r0, min(r0 + chunk_rows, shape[0]))
        codes, br = big[rows], bright[rows]
        for b in range(len(BANDS)):
            t = lut[b][codes]
            t *= br                                                    # float64 product, stored float32
            out[b, rows] = np.clip(np.rint(t * 255.0), 0, 255).astype(np.uint8)
    del bright, big
    # checkerboard panels: 2 x 2 squares, black 0.04 and white 0.8 (flat spectra)
    half = p.target_panel_m / 2
    for xy in targets.values():
        c0 = int((xy[0] - half - grid.x0) / tc)
        r0 = int((grid.y0 - (xy[1] + half)) / tc)
        n = int(round(p.target_panel_m / tc))
        rr, cc = np.mgrid[0:n, 0:n]
        white = ((rr < n // 2) ^ (cc < n // 2))
        panel = np.where(white, 0.8, 0.04).astype(np.float32)
        out[:, r0:r0 + n, c0:c0 + n] = np.clip(np.rint(panel * 255.0), 0, 255).astype(np.uint8)[None]
    return out, tc


# --------------------------------------------------------------------------- flights


def make_camera(cam: Mapping[str, Any], model: str) -> Camera:
    """A kite camera with its principal point at the image centre.

    Parameters
    ----------
    cam : mapping
        The ``camera`` keys of ``lowcost.twin``: image size (px), sensor size and focal length
        (mm), ``k1``.
    model : str
        EXIF model name (the make is ``SONY``).

    Returns
    -------
    Camera
        Focal length ``focal_length_mm · image_width_px / sensor_width_mm`` (px); ``k2`` = 0.
    """
    w, h = int(cam["image_width_px"]), int(cam["image_height_px"])
    f = float(cam["focal_length_mm"]) * w / float(cam["sensor_width_mm"])
    return Camera(width=w, height=h, f=f, cx=(w - 1) / 2.0, cy=(h - 1) / 2.0, k1=float(cam["k1"]), k2=0.0,
                  sensor_width_mm=float(cam["sensor_width_mm"]), sensor_height_mm=float(cam["sensor_height_mm"]),
                  focal_length_mm=float(cam["focal_length_mm"]), make="SONY", model=model)


def flight_poses(p: LowcostTwinParams, sensor: str, seed: int, ground_z: float) -> list[Pose]:
    """Zig-zag of a kite rig: lines along the strip, jittered position, height and attitude;
    image "up" to the north, so the long image side lies along the strip.

    Parameters
    ----------
    p : LowcostTwinParams
        The twin's parameters; ``flight`` gives the lines, spacing, height range and jitter.
    sensor : str
        Camera name (``rgb`` or ``nir``); picks the flight's random stream.
    seed : int
        The run's seed.
    ground_z : float
        Ground height (m) the flight heights are drawn above.

    Returns
    -------
    list of Pose
        Camera poses in flight order.
    """
    f = p.flight
    rng = rng_for(seed, "lowcost", "flight", sensor)
    poses = []
    xs = np.arange(p.origin_xy[0] - f["overrun_m"], p.origin_xy[0] + p.length_m + f["overrun_m"] + 1e-9, f["spacing_m"])
    for li, fy in enumerate(f["lines_y_frac"]):
        y = p.origin_xy[1] + fy * p.width_m
        for x in (xs if li % 2 == 0 else xs[::-1]):
            C = np.array([x + rng.normal(0, f["jitter_m"]), y + rng.normal(0, f["jitter_m"]),
                          ground_z + rng.uniform(*f["height_m"])])
            heading = (0.0 if li % 2 == 0 else 180.0) + rng.normal(0, f["heading_sd_deg"])
            R = nadir_rotation(heading, rng.normal(0, f["tilt_sd_deg"]), rng.normal(0, f["tilt_sd_deg"]))
            poses.append(Pose(R, C))
    return poses


def _project(camera: Camera, pose: Pose, X: np.ndarray) -> np.ndarray:
    """COLMAP pixel coordinates (pixel centres at +0.5) of world points; NaN behind."""
    Xc = pose.world_to_camera(X)
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    r2 = x * x + y * y
    d = 1 + camera.k1 * r2 + camera.k2 * r2 * r2
    uv = np.column_stack([camera.f * x * d + camera.cx + 0.5, camera.f * y * d + camera.cy + 0.5])
    uv[Xc[:, 2] <= 0] = np.nan
    return uv


def render_photo(scene: Scene, camera: Camera, pose: Pose, weights: np.ndarray, effects: Photographic,
                 rng: np.random.Generator, supersampling: int) -> np.ndarray:
    """One 8-bit photo: the texture's four bands ray-cast (``supersampling``² rays per
    pixel), mixed into the camera's channels by ``weights`` (channels x 4 bands, see
    :func:`camera_weights`), then exposure, vignetting, tone curve and noise.

    O(pixels x supersampling²) time; memory about 40 bytes per pixel (the 4-band float32
    reflectance, its channel mix and the effects' float32 arrays): 0.7 GB for a 16 MP photo.

    Parameters
    ----------
    scene : Scene
        Surface and texture prepared by :func:`~kitegully.twin.render.make_scene`.
    camera : Camera
        The kite camera.
    pose : Pose
        Camera pose.
    weights : ndarray (channels, 4)
        Band weights of the camera (texture bands R, G, B, NIR).
    effects : Photographic
        Exposure, vignetting, tone curve and noise settings.
    rng : Generator
        Random stream of the exposure and noise.
    supersampling : int
        Rays per pixel side.

    Returns
    -------
    ndarray (height, width, channels) uint8
        The photo.
    """
    refl, _ = render_reflectance(scene, camera, pose, channels=(0, 1, 2, 3), supersampling=supersampling)
    chans = refl @ weights.T.astype(np.float32)
    del refl
    img, _ = photograph(chans, camera, effects, rng)
    return img


def make_lowcost_twin(cfg: Mapping[str, Any], seed: int, crs: str, out_dir: str | Path) -> dict:
    """Generate the twin: ``<out>/observed/...`` and ``<out>/truth/...``.

    Parameters
    ----------
    cfg : mapping
        The ``lowcost.twin`` section (:class:`LowcostTwinParams`).
    seed : int
        Site seed.
    crs : str
        Site CRS.
    out_dir : path
        Twin folder (``results/<site>/lowcost/twin``).

    Returns
    -------
    dict
        Summary (image counts, GSD, class NDVI), also written to ``truth/summary.json``.

    Cost: O(texture cells + photos x pixels); about 1 s per 1.2 MP photo.
    """
    p = LowcostTwinParams.from_config(cfg)
    out = Path(out_dir)
    obs, truth = out / "observed", out / "truth"
    (obs / "images").mkdir(parents=True, exist_ok=True)
    truth.mkdir(parents=True, exist_ok=True)
    grid, terrain, surface, cls = make_ground(p, seed)
    grid = GridSpec(grid.x0, grid.y0, grid.cell, grid.width, grid.height, crs)
    targets_xy = target_layout(p, seed)
    tex, tcell = make_texture(p, grid, cls, targets_xy, seed)
    scene = make_scene(surface, (grid.x0, grid.y0), grid.cell, tex, (grid.x0, grid.y0), tcell)
    del tex                            # the scene holds its own pyramid of it
    wl = np.arange(400.0, 901.0, 5.0)
    light = sp.illuminant("D65", wl)
    W = camera_weights(wl, light)
    # normalise so that a white panel gives 1 in the brightest channel of each camera
    W = {k: v / v.sum(axis=1).max() for k, v in W.items()}
    names = list(targets_xy)
    txy = np.array([targets_xy[n] for n in names])
    tz = surface_height(scene, txy[:, 0], txy[:, 1])
    T = np.column_stack([txy, tz])
    # waterline: the terrain contour at the tide height, longest piece, evenly sampled
    contours = measure.find_contours(np.asarray(terrain, float), p.tide_m)
    longest = max(contours, key=len)
    pick = longest[np.linspace(0, len(longest) - 1, p.waterline_points + 2).astype(int)[1:-1]]
    wx, wy = grid.x0 + (pick[:, 1] + 0.5) * grid.cell, grid.y0 - (pick[:, 0] + 0.5) * grid.cell
    Wl = np.column_stack([wx, wy, np.full(len(wx), p.tide_m)])
    effects = Photographic.from_config(p.photographic)
    rng_click = rng_for(seed, "lowcost", "clicks")
    clicks, poses_rows = [], []
    t0 = datetime(2012, 2, 14, 10, 0, 0, tzinfo=timezone.utc)
    for k, sensor in enumerate(("rgb", "nir")):
        camera = make_camera(p.camera, "NEX-5" if sensor == "rgb" else "NEX-5 NIR")
        rng = rng_for(seed, "lowcost", "photo", sensor)
        poses = flight_poses(p, sensor, seed, float(np.median(surface)))
        for i, pose in enumerate(poses):
            name = f"{sensor}_{i:03d}.jpg"
            img = render_photo(scene, camera, pose, W[sensor], effects, rng, int(p.flight["supersampling"]))
            when = t0 + timedelta(minutes=15 * k, seconds=2 * i)
            write_jpeg(obs / "images" / name, img, exif_bytes(camera, when, effects.exposure_time_s), 95)
            poses_rows.append({"image": name, "sensor": sensor, "x_m": pose.C[0], "y_m": pose.C[1], "z_m": pose.C[2]})
            for kind, P, ids, sd in (("target", T, names, p.click_sd_px),
                                     ("waterline", Wl, [f"W{j:02d}" for j in range(len(Wl))], p.waterline_click_sd_px)):
                uv = _project(camera, pose, P)
                ok = camera.in_image(uv - 0.5, margin_px=20) & visible(scene, pose, P, 0.05)
                for j in np.flatnonzero(ok):
                    u, v = uv[j] + rng_click.normal(0, sd, 2)
                    clicks.append({"image": name, "kind": kind, "point": ids[j], "u_px": u, "v_px": v})
        log.info("%s flight: %d photos", sensor, len(poses))
    pd.DataFrame(clicks).to_csv(obs / "image_clicks.csv", index=False)
    rng_gps = rng_for(seed, "lowcost", "gps")
    gps = T + rng_gps.normal(0, 1, T.shape) * np.array([p.gps_sd_xy_m, p.gps_sd_xy_m, p.gps_sd_z_m])
    rtk = T + rng_for(seed, "lowcost", "rtk").normal(0, p.rtk_sd_m, T.shape)
    for fname, xyz in (("targets_gps.csv", gps), ("targets_rtk.csv", rtk)):
        pd.DataFrame({"target": names, "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2]}).to_csv(obs / fname, index=False)
    rng_tape = rng_for(seed, "lowcost", "tape")
    tape = []
    for i in range(3):
        tri = [n for n in names if n.startswith(f"T{i + 1}")]
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            d = np.linalg.norm(T[names.index(a)] - T[names.index(b)]) + rng_tape.normal(0, p.tape_sd_m)
            tape.append({"from": a, "to": b, "length_m": round(float(d), 3)})
    pd.DataFrame(tape).to_csv(obs / "tape.csv", index=False)
    (obs / "water_level.json").write_text(json.dumps({"height_m": p.tide_m, "source": "tide table at capture"}) + "\n")
    rng_panel = rng_for(seed, "lowcost", "panel")
    panel = []
    for sensor in ("rgb", "nir"):
        sig = p.panel_reflectance * W[sensor].sum(axis=1) * effects.exposure_gain
        dn = 255.0 * np.clip(sig, 0, 1) ** (1.0 / effects.gamma) + rng_panel.normal(0, 0.1, 3)
        for ch, v in zip(("red", "green", "blue"), dn):
            panel.append({"camera": sensor, "channel": ch, "dn_mean": float(v), "panel_reflectance": p.panel_reflectance})
    pd.DataFrame(panel).to_csv(obs / "panel_shots.csv", index=False)
    # truth
    Raster(surface, grid).write(truth / "dsm.tif")
    Raster(cls, grid, nodata=0).write(truth / "classes.tif")
    table = class_table(p.classes, W)
    write_table(table, truth / "classes.csv")
    pd.DataFrame({"target": names, "x_m": T[:, 0], "y_m": T[:, 1], "z_m": T[:, 2]}).to_csv(truth / "targets.csv", index=False)
    pd.DataFrame(poses_rows).to_csv(truth / "poses.csv", index=False)
    cam = make_camera(p.camera, "NEX-5")
    summary = {"n_rgb": int(sum(r["sensor"] == "rgb" for r in poses_rows)), "n_nir": int(sum(r["sensor"] == "nir" for r in poses_rows)),
               "gsd_m": float(cam.gsd(float(np.mean([r["z_m"] for r in poses_rows]) - np.median(surface)))),
               "class_ndvi_camera": dict(zip(table["class"], table["ndvi_camera"].round(4))),
               "class_ndvi_band": dict(zip(table["class"], table["ndvi_band"].round(4))),
               "class_fraction": {n: float((cls == c).mean()) for n, c in CLASS_CODES.items()}}
    (truth / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
