"""Photographs of a close-range scene taken from a camera on a pole (Mayr et al. 2016, sect. 2.2).

001: a Canon 5D (full frame) with a 24 mm lens on a pole, "several hundred oblique images
per scene taken from multiple positions in an approximately circular pattern around the
eroded area"; 4 white polystyrene spheres (radius 10 cm) as GCPs; a 2 m folding rule laid
as two orthogonal 1 m legs (absent in scene 6).

This module turns a :class:`~kitegully.twin.closerange.CloseRangeScene` (2 cm DEM and
orthophoto) into those photographs:

* :func:`prepare_pole_scene` removes the scene's heightfield marker bumps (a heightfield
  cannot hold a sphere: its bump is a cylinder under a cap) and keeps the true sphere
  centres instead; the orthophoto becomes the texture (upsampled to 1 cm, markers
  in-painted with the surrounding grass); the folding rule is laid as a rigid L resting on the
  ground (:func:`resting_plane`), 2 cm wide, yellow with black decimetre marks, on grass, clear
  of patch and markers, as close to the patch as it fits (inside the ring the photographer
  walks).
* :func:`walk_poses` places the camera ``pole_height_m`` above the ground on a rough
  circle around the eroded patch, aimed at the patch with jitter (oblique views).
* :func:`photograph_walk` ray-casts each view (:mod:`kitegully.twin.render`), adds the
  spheres analytically (:func:`composite_spheres`: exact ray-sphere intersection,
  supersampled, occluded by the terrain depth, Lambert-shaded by the scene's sun), the rule
  likewise (:func:`composite_rule`: two flat strips on its resting plane) and
  applies vignetting and noise (:func:`kitegully.twin.render.photograph`).

The orthophoto texture is already tone-encoded (gamma) and carries the scene's cast
shadows, so the photographs keep its tones (``gamma = 1`` in the camera effects) and the
sphere shading is applied in linear light and re-encoded.  Known simplification: the
mosaic seams of the direct orthophoto are part of the texture.

Cost per image: O(pixels · ray steps) in the numba ray caster (see render.py), plus
O(s² · sphere pixels) for the spheres.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Iterator, Mapping

import cv2
import numpy as np
from scipy import ndimage

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import GridSpec
from kitegully.twin.camera import Camera, Pose
from kitegully.twin.closerange import CloseRangeScene
from kitegully.twin.render import Photographic, Scene, make_scene, photograph, render_reflectance, surface_height

log = logging.getLogger(__name__)

SCENE_GAMMA = 2.2  # tone curve of the scene orthophotos (obia.scenes.camera.gamma)


@dataclass(frozen=True)
class PoleWalk:
    """Acquisition of one scene from a camera on a pole.

    Attributes
    ----------
    n_images : int
        Photos per scene. [P] 001 took 179–676; [I] default 36 keeps a scene's rendering
        near half a minute on one core at 1200 px; SfM needs >= ~20 for a closed ring at 10°
        steps with 24 mm oblique views.
    focal_length_mm, sensor_width_mm, sensor_height_mm : float
        [P] 24 mm on a full-frame (36 × 24 mm) Canon 5D.
    image_width_px, image_height_px : int
        [I] rendered size; 1200 × 800 gives 6 mm per pixel at 4 m (the 2 cm products need
        no more), the real 5D's 5616 px would cost 22× the time.
    pole_height_m : float
        [I] camera above the ground at the photographer's feet (2 m pole held overhead).
    standoff_m : float
        [I] walk radius = the patch's largest centroid distance + this (the photographer
        stays on the grass just outside the patch).
    radius_jitter_m, angle_jitter_deg, aim_jitter_m, roll_sd_deg : float
        [I] a hand-walked circle: radial and angular scatter of the standpoints, scatter of
        the aim point on the ground and of the camera roll.
    supersampling : int
        Rays per pixel side of the terrain ray caster.
    """

    n_images: int = 36
    focal_length_mm: float = 24.0
    sensor_width_mm: float = 36.0
    sensor_height_mm: float = 24.0
    image_width_px: int = 1200
    image_height_px: int = 800
    pole_height_m: float = 3.0
    standoff_m: float = 1.0
    radius_jitter_m: float = 0.3
    angle_jitter_deg: float = 3.0
    aim_jitter_m: float = 0.5
    roll_sd_deg: float = 3.0
    supersampling: int = 1

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "PoleWalk":
        """Build from a config mapping; unknown keys and impossible values raise InputError."""
        config_section(cfg, "pole walk", (), optional=cls.__dataclass_fields__)
        p = cls(**{k: type(getattr(cls, k))(v) for k, v in cfg.items()})
        if p.n_images < 3:
            raise InputError(f"pole walk: n_images is {p.n_images}, at least 3 are needed for a ring of views")
        if p.pole_height_m <= 0 or p.focal_length_mm <= 0:
            raise InputError("pole walk: pole_height_m and focal_length_mm must be positive")
        return p

    def camera(self) -> Camera:
        """Ideal pinhole camera of the walk (principal point at the image centre)."""
        f = self.focal_length_mm * self.image_width_px / self.sensor_width_mm
        return Camera(
            width=self.image_width_px, height=self.image_height_px, f=float(f),
            cx=(self.image_width_px - 1) / 2.0, cy=(self.image_height_px - 1) / 2.0,
            sensor_width_mm=self.sensor_width_mm, sensor_height_mm=self.sensor_height_mm,
            focal_length_mm=self.focal_length_mm, make="Canon", model="EOS 5D",
        )


@dataclass(frozen=True)
class PoleScene:
    """A scene ready to be photographed.

    Attributes
    ----------
    render : Scene
        Ray-caster scene (DEM without marker bumps, 1 cm texture with the folding rule).
    spheres : numpy.ndarray
        (K, 3) true sphere centres (m).
    sphere_radius_m : float
    sphere_dn : numpy.ndarray
        (3,) encoded colour of a fully lit sphere in the texture's tone scale (0–1).
    rule : numpy.ndarray or None
        (3, 3) true folding-rule points: end of leg A, the corner, end of leg B (m).
    patch_centre : numpy.ndarray
        (2,) centroid of the eroded patch (or the scene centre), map x, y.
    patch_reach_m : float
        Largest distance of an eroded cell from that centroid.
    sun : numpy.ndarray
        Unit vector towards the sun (east, north, up).
    diffuse_fraction : float
    """

    render: Scene
    spheres: np.ndarray
    sphere_radius_m: float
    sphere_dn: np.ndarray
    rule: np.ndarray | None
    patch_centre: np.ndarray
    patch_reach_m: float
    sun: np.ndarray
    diffuse_fraction: float


#: [I] Tries per distance limit when laying the rule, and the step by which the limit grows (m).
_RULE_TRIES, _RULE_STEP_M = 100, 0.5


def _rule_corners(grid: GridSpec, centre: np.ndarray, rng: np.random.Generator) -> Iterator[tuple[np.ndarray, float]]:
    """Candidate corners of the rule and the distance from ``centre`` its points may reach.

    [I] The operator lays the scale bar on grass as close to the eroded area as it fits
    (001: the area of interest, "the eroded area and its direct surroundings", is where the
    point density is high; the periphery, beyond the camera ring, is matched poorly and the
    products are cropped to the ring): limits from 1 m (a leg's length) out in 0.5 m steps,
    ``_RULE_TRIES`` uniform corners within each limit's disc, until the scene's corners.
    """
    h, w = grid.height, grid.width
    lo = np.array([grid.x0 + 0.2, grid.y0 - h * grid.cell + 0.2])
    hi = np.array([grid.x0 + w * grid.cell - 0.2, grid.y0 - 0.2])
    far = float(np.hypot(*np.maximum(np.abs(lo - centre), np.abs(hi - centre))))
    for limit in np.arange(1.0, far + _RULE_STEP_M, _RULE_STEP_M):
        for _ in range(_RULE_TRIES):
            rad, ang = limit * np.sqrt(rng.uniform()), rng.uniform(0, 2 * np.pi)
            corner = np.clip(centre + rad * np.array([np.cos(ang), np.sin(ang)]), lo, hi)
            yield corner, float(limit)


#: [P] the folding rule's strip: 2 cm wide, 3 mm thick, yellow with a 1 cm black mark centred on each
#: decimetre (half marks at the corner and the ends); colours tone-encoded, full light.
RULE_WIDTH_M, RULE_THICKNESS_M, RULE_MARK_M = 0.02, 0.003, 0.01
RULE_YELLOW, RULE_BLACK = (0.93, 0.80, 0.20), (0.08, 0.08, 0.08)


def _bilinear(dem: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear DEM height at map points (the ray caster's surface, cell centres at integers)."""
    r, c = grid.rowcol(x, y)
    return ndimage.map_coordinates(dem, [np.ravel(r), np.ravel(c)], order=1, mode="nearest")


def _legs(phi: float, sign: float, ga: float, gb: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit 3-D legs of the rule in the plane of slopes ``(ga, gb)``: leg A at plan azimuth ``phi``, B = ±n × A; and n."""
    normal = np.array([-ga, -gb, 1.0]) / np.sqrt(ga * ga + gb * gb + 1.0)
    t1 = np.array([np.cos(phi), np.sin(phi), ga * np.cos(phi) + gb * np.sin(phi)])
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(normal, t1) * sign, normal


def resting_plane(dem: np.ndarray, grid: GridSpec, corner: np.ndarray, phi: float, sign: float, ga: float, gb: float,
                  iterations: int = 2) -> tuple[float, float, float]:
    """Plane ``z = corner_z + ga·dx + gb·dy`` on which a rigid L rule rests on the ground: ``(ga, gb, corner_z)``.

    A rigid rule laid on grass does not follow the tussocks: it rests on the highest points
    under it.  The plane is the lowest one above the surface under the rule's two strips
    (sampled every centimetre along the legs, at its centre line and both edges): the
    linear programme ``min Σ (plane − surface)`` subject to ``plane >= surface``, whose
    solution touches the ground at (generically) three points, as a rigid body comes to
    rest.  The strips' plan footprint depends on the plane's tilt (legs of 1 m in 3-D), so
    it is re-solved ``iterations`` times from the previous plane (start: the least-squares
    plane ``ga, gb``).  O(iterations · samples) plus a 3-variable LP.

    Parameters
    ----------
    dem : ndarray (H, W)
        Surface heights (m) on ``grid``.
    grid : GridSpec
        The DEM's grid.
    corner : ndarray (2,)
        Map x, y of the rule's corner (m).
    phi : float
        Plan azimuth of leg A (rad, anticlockwise from +x).
    sign : float
        +1 or −1: the side to which leg B turns from leg A.
    ga, gb : float
        Slopes ``dz/dx`` and ``dz/dy`` of the starting plane.
    iterations : int
        Number of solves.

    Returns
    -------
    ga, gb : float
        Slopes of the resting plane.
    corner_z : float
        Height of the plane at the corner (m).
    """
    from scipy.optimize import linprog

    corner = np.asarray(corner, float)
    s = np.arange(-0.5 * RULE_WIDTH_M, 1.0 + 1e-9, 0.01)
    c0 = float(_bilinear(dem, grid, corner[:1], corner[1:])[0])
    for _ in range(iterations):
        t1, t2, _n = _legs(phi, sign, ga, gb)
        pts = []
        for u, v in ((t1, t2), (t2, t1)):
            for a in (-0.5 * RULE_WIDTH_M, 0.0, 0.5 * RULE_WIDTH_M):
                pts.append(s[:, None] * u[None, :2] + a * v[None, :2])
        d = np.vstack(pts)
        h = _bilinear(dem, grid, corner[0] + d[:, 0], corner[1] + d[:, 1])
        A = np.column_stack([d, np.ones(len(d))])
        res = linprog(A.sum(axis=0), A_ub=-A, b_ub=-h, bounds=[(None, None)] * 3, method="highs")
        if not res.success:  # cannot happen for an L (its samples are not collinear); keep the last plane
            break
        ga, gb, c0 = (float(x) for x in res.x)
    return ga, gb, c0


def _lay_rule(grid: GridSpec, free: np.ndarray, dem: np.ndarray, rng: np.random.Generator, centre: np.ndarray) -> np.ndarray:
    """Lay a rigid 2 m folding rule as two orthogonal 1 m legs resting on the ground; return its points.

    The rule is rigid and straight: its legs are 1 m long and orthogonal in 3-D.  Its
    place: on free grass as close to ``centre`` (the eroded patch's centroid) as it fits
    (:func:`_rule_corners`), with leg A at a random plan azimuth in the plane fitted to the
    DEM within 1 m of the corner (on a 35° slope a downslope leg covers 0.82 m in plan) and
    leg B turned by ±90° in that plane.  Its height and tilt: the plane it comes to rest on
    (:func:`resting_plane`), the top of the 3 mm strip being the measured surface.  It is
    drawn into each photo as a 3-D object (:func:`composite_rule`), not painted onto the
    terrain's texture: painted, it followed the grass tussocks (±10 cm in scene 05), so the
    photographed legs were 0.98–1.06 m long in 3-D and bent in the photos (issue 20,
    ``benchmarks/closerange_rule_diagnosis.py``).  Returns the (3, 3) points on the strip's
    top centre line: end of leg A, corner, end of leg B.
    """
    cell = grid.cell
    h, w = dem.shape
    xs, ys = grid.cell_centres()
    centre = np.asarray(centre, float)
    for corner, limit in _rule_corners(grid, centre, rng):
        r0, c0 = (int(v) for v in np.rint(grid.rowcol(corner[0], corner[1])))
        k = int(round(1.0 / cell))
        win = (slice(max(r0 - k, 0), min(r0 + k + 1, h)), slice(max(c0 - k, 0), min(c0 + k + 1, w)))
        X, Y = np.meshgrid(xs[win[1]] - corner[0], ys[win[0]] - corner[1])
        A = np.column_stack([X.ravel(), Y.ravel(), np.ones(X.size)])
        ga, gb, gc = np.linalg.lstsq(A, dem[win].ravel(), rcond=None)[0]
        phi = rng.uniform(0, 2 * np.pi)
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        t1, t2, _n = _legs(phi, sign, ga, gb)
        s = np.linspace(0.0, 1.0, 101)
        pts = np.vstack([corner[:2] + s[:, None] * t1[:2], corner[:2] + s[:, None] * t2[:2]])
        if np.hypot(pts[:, 0] - centre[0], pts[:, 1] - centre[1]).max() > limit:
            continue
        r, c = grid.rowcol(pts[:, 0], pts[:, 1])
        r, c = np.rint(r).astype(int), np.rint(c).astype(int)
        if r.min() < 0 or c.min() < 0 or r.max() >= h or c.max() >= w or not free[r, c].all():
            continue
        ga, gb, z0 = resting_plane(dem, grid, corner, phi, sign, float(ga), float(gb))
        t1, t2, _n = _legs(phi, sign, ga, gb)
        c3 = np.array([corner[0], corner[1], z0 + RULE_THICKNESS_M])
        return np.vstack([c3 + t1, c3, c3 + t2])
    raise InputError("folding rule: no 1 m x 1 m spot on grass clear of the patch and the markers in the scene")


def composite_rule(
    refl: np.ndarray, depth: np.ndarray, camera: Camera, pose: Pose, rule: np.ndarray, sun: np.ndarray, diffuse: float,
    supersampling: int = 4,
) -> np.ndarray:
    """Draw the rigid folding rule into a rendered image (in place and returned), occluded by the terrain.

    ``rule`` is (3, 3): end of leg A, corner, end of leg B on the strip's top centre line.
    Each leg is a flat strip ``RULE_WIDTH_M`` wide from half a width behind the corner to
    its end, yellow with a black ``RULE_MARK_M`` mark centred on each decimetre.  Each pixel
    of the legs' bounding box gets ``s × s`` rays; a ray hits a strip where it meets the
    rule's plane inside the strip nearer than the terrain depth (as
    :func:`composite_spheres`); the paint is Lambert-shaded by the scene's sun in linear
    light and re-encoded.  O(s² · bounding-box pixels).

    Parameters
    ----------
    refl : ndarray (height, width, 3) float
        Rendered reflectance (0–1); changed in place.
    depth : ndarray (height, width)
        Terrain distance along each pixel's ray (m), NaN where nothing was hit.
    camera : Camera
        The camera.
    pose : Pose
        The camera pose.
    rule : ndarray (3, 3)
        The rule's points (m), as above.
    sun : ndarray (3,)
        Unit vector towards the sun (east, north, up).
    diffuse : float
        Diffuse fraction of the light (0–1).
    supersampling : int
        ``s``: rays per pixel side.

    Returns
    -------
    ndarray
        ``refl``, with the rule drawn in.
    """
    a_end, C, b_end = (np.asarray(p, float) for p in rule)
    ua, ub = a_end - C, b_end - C
    la, lb = np.linalg.norm(ua), np.linalg.norm(ub)
    ua, ub = ua / la, ub / lb
    n = np.cross(ua, ub)
    n /= np.linalg.norm(n)
    if n[2] < 0:
        n = -n
    hw = 0.5 * RULE_WIDTH_M
    legs = [(ua, np.cross(n, ua), la), (ub, np.cross(n, ub), lb)]
    corners = np.vstack([[C + s * u + q * v for s in (-hw, L) for q in (-hw, hw)] for u, v, L in legs])
    uv = camera.project(corners, pose)
    if not np.isfinite(uv).all():
        return refl
    h, w = refl.shape[:2]
    u0, v0 = (int(np.floor(x)) - 2 for x in uv.min(axis=0))
    u1, v1 = (int(np.ceil(x)) + 2 for x in uv.max(axis=0))
    u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w - 1), min(v1, h - 1)
    if u1 < u0 or v1 < v0:
        return refl
    offs = (np.arange(supersampling) + 0.5) / supersampling - 0.5
    uu, vv = np.meshgrid(np.arange(u0, u1 + 1), np.arange(v0, v1 + 1))
    su, sv = np.broadcast_arrays(uu[..., None, None] + offs[None, None, None, :], vv[..., None, None] + offs[None, None, :, None])
    su, sv = su.reshape(*uu.shape, -1), sv.reshape(*uu.shape, -1)
    d = camera.rays_camera(su, sv) @ pose.R
    den = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((C - pose.C) @ n) / den
    H = pose.C + t[..., None] * d - C
    tz = depth[v0:v1 + 1, u0:u1 + 1][..., None]
    visible = (t > 0) & np.isfinite(t) & (~np.isfinite(tz) | (t < tz + 1e-3))
    col = np.zeros(t.shape + (3,))
    hit = np.zeros(t.shape, bool)
    for u, v, L in legs:  # leg B last: it wins in the corner square (both are the same plane there)
        along, across = H @ u, H @ v
        on = visible & (along >= -hw) & (along <= L) & (np.abs(across) <= hw)
        mark = np.abs(along - np.round(along, 1)) <= 0.5 * RULE_MARK_M
        col = np.where(on[..., None], np.where(mark[..., None], RULE_BLACK, RULE_YELLOW), col)
        hit |= on
    shade = (diffuse + (1.0 - diffuse) * max(float(n @ sun), 0.0)) ** (1.0 / SCENE_GAMMA)
    cover = hit.mean(axis=-1)
    mean = np.where(hit[..., None], col, 0.0).sum(axis=-2) / np.maximum(hit.sum(axis=-1), 1)[..., None]
    patch = refl[v0:v1 + 1, u0:u1 + 1]
    patch[:] = (1 - cover[..., None]) * patch + cover[..., None] * (shade * mean)
    return refl


def prepare_pole_scene(scene: CloseRangeScene, sphere_radius_m: float, folding_rule: bool, rng: np.random.Generator) -> PoleScene:
    """Scene for the pole-camera photographs (see module doc).

    Parameters
    ----------
    scene
        A generated close-range scene (twin: its truth masks are used to build it).
    sphere_radius_m
        [P] 0.10 m.
    folding_rule
        Lay the rule ([P] all scenes but scene 6).
    rng
        Random stream for the rule's placement.
    """
    g = scene.grid
    dem = scene.dem.astype(np.float64).copy()
    lab, n = ndimage.label(scene.truth_markers > 0)
    centres = []
    for k in range(1, n + 1):
        blob = lab == k
        # the generator raised the blob to ground + r + cap (cap = r at the centre): the
        # ground under the sphere, where the survey put its centre - r, is the top - 2r
        ground = float(dem[blob].max()) - 2.0 * sphere_radius_m
        dem[blob] = ground
        rr, cc = np.nonzero(blob)
        xs, ys = g.x0 + (cc.mean() + 0.5) * g.cell, g.y0 - (rr.mean() + 0.5) * g.cell
        centres.append((xs, ys, ground + sphere_radius_m))
    rgb = np.moveaxis(scene.rgb, 0, -1)
    mk = scene.truth_markers > 0
    sphere_dn = (np.median(rgb[mk], axis=0) / 255.0) if mk.any() else np.array([0.95, 0.95, 0.95])
    tex = cv2.inpaint(np.ascontiguousarray(rgb), ndimage.binary_dilation(mk, iterations=1).astype(np.uint8), 3, cv2.INPAINT_TELEA)
    tex = cv2.resize(tex, (2 * g.width, 2 * g.height), interpolation=cv2.INTER_LINEAR).astype(np.float32) / 255.0
    eroded = scene.truth_eroded > 0
    if eroded.any():
        rr, cc = np.nonzero(eroded)
        px, py = g.x0 + (cc + 0.5) * g.cell, g.y0 - (rr + 0.5) * g.cell
        centre = np.array([px.mean(), py.mean()])
        reach = float(np.hypot(px - centre[0], py - centre[1]).max())
    else:
        centre = np.array([g.x0 + g.width * g.cell / 2, g.y0 - g.height * g.cell / 2])
        reach = 0.0
    rule = None
    if folding_rule:
        clear = int(round(0.3 / g.cell))
        busy = ndimage.binary_dilation(eroded | mk, iterations=clear)
        rule = _lay_rule(g, ~busy, dem, rng, centre)
    texture = np.clip(np.rint(tex * 255), 0, 255).astype(np.uint8).transpose(2, 0, 1)
    render = make_scene(dem.astype(np.float32), (g.x0, g.y0), g.cell, texture, (g.x0, g.y0), g.cell / 2, band_names=("R", "G", "B"))
    el, az = np.radians(scene.meta["sun_elevation_deg"]), np.radians(scene.meta["sun_azimuth_deg"])
    sun = np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    return PoleScene(render, np.array(centres).reshape(-1, 3), float(sphere_radius_m), np.asarray(sphere_dn, float), rule,
                     centre, reach, sun, float(scene.meta["diffuse_fraction"]))


def look_at(C: np.ndarray, target: np.ndarray, roll_rad: float = 0.0) -> np.ndarray:
    """World → camera rotation of a camera at ``C`` looking at ``target`` (image x to the right, level horizon).

    Parameters
    ----------
    C : ndarray (3,)
        Camera centre (m).
    target : ndarray (3,)
        World point on the optical axis (m).
    roll_rad : float
        Roll about the optical axis (rad).

    Returns
    -------
    ndarray (3, 3)
    """
    z = np.asarray(target, float) - np.asarray(C, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.vstack([x, y, z])
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ R


def _ground_plane(render: Scene):
    """Least-squares plane through the scene's DEM (every 5th cell), as ``z(x, y)``."""
    dem = render.dsm[::5, ::5].astype(np.float64)
    r, c = np.nonzero(np.isfinite(dem))
    X = render.x0 + (c * 5 + 0.5) * render.cell
    Y = render.y0 - (r * 5 + 0.5) * render.cell
    a, b, z0 = np.linalg.lstsq(np.column_stack([X - render.x0, Y - render.y0, np.ones(len(X))]), dem[r, c], rcond=None)[0]
    return lambda x, y: a * (np.asarray(x) - render.x0) + b * (np.asarray(y) - render.y0) + z0


def ground_reach(render: Scene, centre: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Distance (m) from ``centre`` to the edge of the rendered DEM along each direction ``angles`` (rad from +x).

    Parameters
    ----------
    render : Scene
        The rendered scene; its DEM's footprint is used.
    centre : ndarray (2,)
        Map x, y of the start point (m).
    angles : ndarray
        Directions (rad, anticlockwise from +x).

    Returns
    -------
    ndarray
        Distance (m, ≥ 0) per direction.
    """
    h, w = render.dsm.shape
    x0, x1 = render.x0, render.x0 + w * render.cell
    y1, y0 = render.y0, render.y0 - h * render.cell
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(c > 0, (x1 - centre[0]) / c, np.where(c < 0, (x0 - centre[0]) / c, np.inf))
        ty = np.where(s > 0, (y1 - centre[1]) / s, np.where(s < 0, (y0 - centre[1]) / s, np.inf))
    return np.maximum(np.minimum(tx, ty), 0.0)


def walk_poses(
    pscene: PoleScene, walk: PoleWalk, rng: np.random.Generator, max_radius_m: float | None = None,
    min_radius_m: float | None = None,
) -> list[Pose]:
    """Camera poses on a rough ring around the patch, aimed at it (oblique views).

    The nominal radius is ``patch_reach_m + standoff_m`` (optionally capped at
    ``max_radius_m``).  The photographer stands on the ground that exists: along each
    direction the radius is pulled in to the rendered DEM's edge less ``2 × radius_jitter_m``
    (the foot stays on the ground for 95 % of the hand-walked scatter), but never below
    ``min_radius_m`` (the patch's reach + standoff: the photographer does not walk on the
    patch).  Beyond the rendered DEM there is no ground to photograph (the renderer shows a
    uniform background), so a camera standing off it sees its near field empty and the
    ring loses overlap (scenes 04/05 did not connect with a ring 2.5–3 m off the DEM).
    Ground heights come from the DEM (bilinear; off the DEM from the plane fitted to it),
    the camera is ``pole_height_m`` above them.

    Parameters
    ----------
    pscene : PoleScene
        The scene.
    walk : PoleWalk
        Number of images, pole height, standoff and jitters.
    rng : numpy.random.Generator
        Random stream for the jitters.
    max_radius_m : float or None
        Cap on the nominal radius (m); None for none.
    min_radius_m : float or None
        Least radius (m) when pulling the ring in to the DEM's edge; None keeps the nominal radius.

    Returns
    -------
    list of Pose
        ``walk.n_images`` poses, in order round the ring.
    """
    radius = pscene.patch_reach_m + walk.standoff_m
    if max_radius_m is not None:
        radius = min(radius, max_radius_m)
    k = np.arange(walk.n_images)
    ang = 2 * np.pi * k / walk.n_images + np.radians(walk.angle_jitter_deg) * rng.standard_normal(walk.n_images)
    rad = np.full(walk.n_images, radius)
    if min_radius_m is not None:
        on_ground = ground_reach(pscene.render, pscene.patch_centre, ang) - 2.0 * walk.radius_jitter_m
        rad = np.minimum(rad, np.maximum(on_ground, min(min_radius_m, radius)))
    rad = rad + walk.radius_jitter_m * rng.standard_normal(walk.n_images)
    x = pscene.patch_centre[0] + rad * np.cos(ang)
    y = pscene.patch_centre[1] + rad * np.sin(ang)
    plane = _ground_plane(pscene.render)
    zg = surface_height(pscene.render, x, y)
    zg = np.where(np.isnan(zg), plane(x, y), zg)  # off the DEM: the slope's plane, extended
    aim = pscene.patch_centre[None] + walk.aim_jitter_m * rng.standard_normal((walk.n_images, 2))
    za = surface_height(pscene.render, aim[:, 0], aim[:, 1])
    za = np.where(np.isnan(za), plane(aim[:, 0], aim[:, 1]), za)
    poses = []
    for i in range(walk.n_images):
        C = np.array([x[i], y[i], zg[i] + walk.pole_height_m])
        R = look_at(C, np.array([aim[i, 0], aim[i, 1], za[i]]), np.radians(walk.roll_sd_deg) * rng.standard_normal())
        poses.append(Pose(R, C))
    return poses


def composite_spheres(
    refl: np.ndarray, depth: np.ndarray, camera: Camera, pose: Pose, centres: np.ndarray, radius: float,
    colour: np.ndarray, sun: np.ndarray, diffuse: float, supersampling: int = 4,
) -> np.ndarray:
    """Draw spheres into a rendered image (in place and returned), occluded by the terrain.

    Each pixel of a sphere's bounding box gets ``s × s`` rays; a ray hits the sphere where
    ``|C + t d − S| = r`` has a root nearer than the terrain depth.  Coverage blends the
    sphere's shaded colour (Lambert: ``diffuse + (1 − diffuse)·max(n·sun, 0)``, in linear
    light, re-encoded with the scene gamma) with the terrain's.

    Parameters
    ----------
    refl : ndarray (height, width, 3) float
        Rendered reflectance (0–1); changed in place.
    depth : ndarray (height, width)
        Terrain distance along each pixel's ray (m), NaN where nothing was hit.
    camera : Camera
        The camera.
    pose : Pose
        The camera pose.
    centres : ndarray (K, 3)
        Sphere centres (m).
    radius : float
        Sphere radius (m).
    colour : ndarray (3,)
        Encoded colour of a fully lit sphere (0–1).
    sun : ndarray (3,)
        Unit vector towards the sun (east, north, up).
    diffuse : float
        Diffuse fraction of the light (0–1).
    supersampling : int
        ``s``: rays per pixel side.

    Returns
    -------
    ndarray
        ``refl``, with the spheres drawn in.
    """
    h, w = refl.shape[:2]
    inv = 1.0 / supersampling
    offs = (np.arange(supersampling) + 0.5) * inv - 0.5
    for S in np.atleast_2d(centres):
        Xc = pose.world_to_camera(S[None])[0]
        dist = np.linalg.norm(Xc)
        if Xc[2] <= radius or dist <= radius:
            continue
        uv = camera.project_camera(Xc[None])[0]
        rad_px = camera.f * radius / np.sqrt(dist ** 2 - radius ** 2) * (1 + np.hypot(Xc[0], Xc[1]) ** 2 / Xc[2] ** 2) + 3
        u0, u1 = int(np.floor(uv[0] - rad_px)), int(np.ceil(uv[0] + rad_px))
        v0, v1 = int(np.floor(uv[1] - rad_px)), int(np.ceil(uv[1] + rad_px))
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w - 1), min(v1, h - 1)
        if u1 < u0 or v1 < v0:
            continue
        uu, vv = np.meshgrid(np.arange(u0, u1 + 1), np.arange(v0, v1 + 1))
        su, sv = np.broadcast_arrays(uu[..., None, None] + offs[None, None, None, :], vv[..., None, None] + offs[None, None, :, None])
        su, sv = su.reshape(*uu.shape, -1), sv.reshape(*uu.shape, -1)
        d_cam = camera.rays_camera(su, sv)
        d = d_cam @ pose.R  # camera → world
        oc = pose.C - S
        b = d @ oc
        disc = b * b - (oc @ oc - radius * radius)
        hit = disc > 0
        t = -b - np.sqrt(np.where(hit, disc, 0.0))
        tz = depth[v0:v1 + 1, u0:u1 + 1][..., None]
        hit &= (t > 0) & (~np.isfinite(tz) | (t < tz + 1e-3))
        P = pose.C + t[..., None] * d
        nrm = (P - S) / radius
        shade = diffuse + (1.0 - diffuse) * np.clip(nrm @ sun, 0.0, None)
        enc = shade[..., None] ** (1.0 / SCENE_GAMMA) * colour
        cover = hit.mean(axis=-1)
        col = np.where(hit[..., None], enc, 0.0).sum(axis=-2) / np.maximum(hit.sum(axis=-1), 1)[..., None]
        patch = refl[v0:v1 + 1, u0:u1 + 1]
        patch[:] = (1 - cover[..., None]) * patch + cover[..., None] * col
    return refl


def project_spheres(camera: Camera, pose: Pose, centres: np.ndarray) -> np.ndarray:
    """True images (px) of the sphere centres, NaN behind the camera.

    Parameters
    ----------
    camera : Camera
        The camera.
    pose : Pose
        The camera pose.
    centres : ndarray (K, 3)
        Sphere centres (m).

    Returns
    -------
    ndarray (K, 2)
        Pixel positions (px).
    """
    return camera.project(np.atleast_2d(centres), pose)


def photograph_walk(
    pscene: PoleScene, walk: PoleWalk, poses: list[Pose], rng: np.random.Generator,
    effects: Photographic | None = None,
) -> Iterator[tuple[int, np.ndarray]]:
    """Render the photos of a walk one by one: yields ``(index, uint8 RGB image)``.

    ``effects`` default: the scene's tones (gamma 1), 0.1 EV exposure scatter, 20 %
    vignetting, read and shot noise.

    Parameters
    ----------
    pscene : PoleScene
        The scene.
    walk : PoleWalk
        Gives the camera and the supersampling.
    poses : list of Pose
        Camera poses, as from :func:`walk_poses`.
    rng : numpy.random.Generator
        Random stream for exposure and noise.
    effects : Photographic or None
        Camera effects; None for the default above.

    Yields
    ------
    index : int
        Position of the pose in ``poses``.
    image : ndarray (height, width, 3) uint8
        The photograph.
    """
    cam = walk.camera()
    fx = effects or Photographic(exposure_gain=1.0, exposure_ev_sd=0.1, vignetting=0.2, gamma=1.0,
                                 read_noise_dn=1.0, shot_noise_dn2_per_dn=0.05, exposure_time_s=0.002)
    bg = (0.55, 0.65, 0.8)  # sky/far hillside where a ray leaves the scene
    for i, pose in enumerate(poses):
        refl, depth = render_reflectance(pscene.render, cam, pose, (0, 1, 2), walk.supersampling, bg)
        composite_spheres(refl, depth, cam, pose, pscene.spheres, pscene.sphere_radius_m, pscene.sphere_dn,
                          pscene.sun, pscene.diffuse_fraction)
        if pscene.rule is not None:
            composite_rule(refl, depth, cam, pose, pscene.rule, pscene.sun, pscene.diffuse_fraction)
        img, _ = photograph(refl, cam, fx, rng)
        if (i + 1) % 10 == 0 or i + 1 == len(poses):
            log.info("pole walk: rendered %d/%d photos", i + 1, len(poses))
        yield i, img
