"""Ray-cast rendering of a DSM heightfield with a reflectance texture, plus camera effects.

A :class:`Scene` holds the surface model (float32, NaN = no surface), a conservative
block-maximum grid for empty-space skipping, and a mip-map pyramid of the multi-band
texture. :func:`render_reflectance` casts one or more rays per pixel through the camera
model (radial distortion inverted per ray), finds the first intersection with the
bilinear surface (so gully banks, shrubs and buildings occlude what lies behind them),
and samples the texture trilinearly from the mip level that matches the pixel's ground
footprint (antialiasing). :func:`photograph` then applies exposure, vignetting, a tone
curve, motion blur and sensor noise, and returns 8-bit RGB ready for JPEG.

Cost: O(pixels · s² · (n_coarse + n_fine)) per image, where s is the supersampling factor,
n_coarse ≈ relief·tan(view angle)/block size and n_fine ≈ 2 block size / cell for the
block holding the hit; compiled with numba and parallel over image rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import cv2
import numba
import numpy as np
from scipy import ndimage

from kitegully.twin.camera import Camera, Pose


@dataclass(frozen=True)
class Scene:
    """Surface and texture, ready for the ray caster (see :func:`make_scene`)."""

    dsm: np.ndarray
    x0: float
    y0: float
    cell: float
    block: int
    block_max: np.ndarray
    super_block: int
    super_max: np.ndarray
    zmin: float
    zmax: float
    tex: np.ndarray
    tex_offsets: np.ndarray
    tex_shapes: np.ndarray
    tex_x0: float
    tex_y0: float
    tex_cell: float
    nbands: int
    band_names: tuple[str, ...]

    def cast_args(self) -> tuple:
        """The scene's arguments of the ray-casting kernel (``dsm`` … ``zmax``), in its order."""
        return (self.dsm, self.x0, self.y0, self.cell, self.block_max, self.block, self.super_max,
                self.block * self.super_factor, self.zmin, self.zmax)

    @property
    def super_factor(self) -> int:
        """Blocks per super-block side."""
        return self.super_block // self.block


def _mip_levels(texture: np.ndarray, min_size: int = 8) -> list[np.ndarray]:
    """Box-filtered 2× pyramid of a (bands, rows, cols) uint8 texture as (rows, cols, bands)."""
    lvl = np.ascontiguousarray(np.moveaxis(texture, 0, -1))
    levels = [lvl]
    while min(lvl.shape[:2]) >= 2 * min_size:
        h, w = (lvl.shape[0] // 2) * 2, (lvl.shape[1] // 2) * 2
        x = lvl[:h, :w].astype(np.uint16)
        lvl = ((x[0::2, 0::2] + x[1::2, 0::2] + x[0::2, 1::2] + x[1::2, 1::2] + 2) // 4).astype(np.uint8)
        levels.append(np.ascontiguousarray(lvl))
    return levels


def _mip_shapes(rows: int, cols: int, min_size: int = 8) -> list[tuple[int, int]]:
    """(rows, cols) of each level of :func:`_mip_levels`'s pyramid."""
    shapes = [(rows, cols)]
    while min(shapes[-1]) >= 2 * min_size:
        shapes.append((shapes[-1][0] // 2, shapes[-1][1] // 2))
    return shapes


def _mip_flat(texture: np.ndarray, min_size: int = 8, chunk_cells: int = 1 << 22) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_mip_levels`'s pyramid written straight into one flat uint8 buffer.

    Returns the buffer (levels as (rows, cols, bands) one after the other), each level's
    offset and its (rows, cols). Equal, byte for byte, to concatenating
    :func:`_mip_levels`; level 0 is transposed and each level reduced about
    ``chunk_cells`` cells at a time, so the only memory beyond the buffer (4/3 of the
    texture) is a chunk. O(texture cells).
    """
    nb, rows, cols = texture.shape
    shapes = _mip_shapes(rows, cols, min_size)
    sizes = [r * c * nb for r, c in shapes]
    offsets = np.cumsum([0] + sizes[:-1]).astype(np.int64)
    flat = np.empty(int(sum(sizes)), dtype=np.uint8)
    step = max(1, chunk_cells // max(cols, 1))
    prev = flat[: sizes[0]].reshape(rows, cols, nb)
    for r0 in range(0, rows, step):
        prev[r0:r0 + step] = np.moveaxis(texture[:, r0:r0 + step], 0, -1)
    for (r, c), off, size in zip(shapes[1:], offsets[1:], sizes[1:]):
        cur = flat[off:off + size].reshape(r, c, nb)
        for r0 in range(0, r, step):
            r1 = min(r0 + step, r)
            x = prev[2 * r0:2 * r1, : 2 * c].astype(np.uint16)
            cur[r0:r1] = ((x[0::2, 0::2] + x[1::2, 0::2] + x[0::2, 1::2] + x[1::2, 1::2] + 2) // 4).astype(np.uint8)
        prev = cur
    return flat, offsets, np.array(shapes, dtype=np.int64).reshape(-1, 2)


def make_scene(
    dsm: np.ndarray,
    dsm_origin: tuple[float, float],
    dsm_cell: float,
    texture: np.ndarray,
    tex_origin: tuple[float, float],
    tex_cell: float,
    band_names: Sequence[str] = ("R", "G", "B", "NIR"),
    block: int = 16,
) -> Scene:
    """Prepare a scene for ray casting.

    Parameters
    ----------
    dsm
        Surface heights (rows south, cols east), float, NaN where there is no surface.
    dsm_origin, tex_origin
        Map coordinates (x, y) of the top-left corner of each grid.
    dsm_cell, tex_cell
        Cell sizes (m).
    texture
        (bands, rows, cols) uint8 reflectance × 255.
    block
        Block size (cells) of the empty-space-skipping maximum grid.

    Memory: the DSM (float32), 4/3 of the texture (uint8 pyramid, built in place in one
    buffer: no more than the caller's texture and this pyramid at any time) and a small
    block grid.
    """
    dsm = np.ascontiguousarray(dsm, dtype=np.float32)
    if texture.ndim == 2:
        texture = texture[None]
    h, w = dsm.shape
    nb_r, nb_c = -(-h // block), -(-w // block)
    pad = np.full((nb_r * block + 1, nb_c * block + 1), -np.inf, dtype=np.float32)
    pad[:h, :w] = np.where(np.isnan(dsm), -np.inf, dsm)
    # Each block's max includes its bilinear neighbours (one extra row/col), then dilate 3×3
    # so a ray step of one block length may start anywhere inside the block.
    core = pad[: nb_r * block, : nb_c * block].reshape(nb_r, block, nb_c, block).max(axis=(1, 3))
    right = pad[: nb_r * block, block::block][:, :nb_c].reshape(nb_r, block, -1).max(axis=1)
    below = pad[block::block, : nb_c * block][:nb_r].reshape(-1, nb_c, block).max(axis=2)
    bmax = np.maximum(core, np.maximum(right, below))
    sf = 8
    sr, sc = -(-nb_r // sf), -(-nb_c // sf)
    spad = np.full((sr * sf, sc * sf), -np.inf, dtype=np.float32)
    spad[:nb_r, :nb_c] = bmax
    smax = spad.reshape(sr, sf, sc, sf).max(axis=(1, 3))
    smax = ndimage.maximum_filter(smax, size=3, mode="nearest").astype(np.float32)
    bmax = ndimage.maximum_filter(bmax, size=3, mode="nearest").astype(np.float32)
    finite = dsm[np.isfinite(dsm)]
    if finite.size == 0:
        raise ValueError("DSM has no valid cells")
    flat, offsets, shapes = _mip_flat(np.asarray(texture, dtype=np.uint8))
    return Scene(
        dsm=dsm,
        x0=float(dsm_origin[0]),
        y0=float(dsm_origin[1]),
        cell=float(dsm_cell),
        block=int(block),
        block_max=bmax,
        super_block=int(block * sf),
        super_max=smax,
        zmin=float(finite.min()),
        zmax=float(finite.max()),
        tex=flat,
        tex_offsets=offsets,
        tex_shapes=shapes,
        tex_x0=float(tex_origin[0]),
        tex_y0=float(tex_origin[1]),
        tex_cell=float(tex_cell),
        nbands=int(texture.shape[0]),
        band_names=tuple(band_names),
    )


# --------------------------------------------------------------------------- numba core


@numba.njit(cache=True, inline="always")
def _height(dsm, x0, y0, cell, x, y):
    """Bilinear DSM height at (x, y); -inf outside the grid or next to NaN."""
    h, w = dsm.shape
    c = (x - x0) / cell - 0.5
    r = (y0 - y) / cell - 0.5
    if c < -0.5 or r < -0.5 or c > w - 0.5 or r > h - 0.5:
        return -np.inf
    c = min(max(c, 0.0), w - 1.0)
    r = min(max(r, 0.0), h - 1.0)
    c0 = min(int(c), w - 2) if w > 1 else 0
    r0 = min(int(r), h - 2) if h > 1 else 0
    fc = c - c0
    fr = r - r0
    c1 = min(c0 + 1, w - 1)
    r1 = min(r0 + 1, h - 1)
    z = (dsm[r0, c0] * (1 - fc) + dsm[r0, c1] * fc) * (1 - fr) + (dsm[r1, c0] * (1 - fc) + dsm[r1, c1] * fc) * fr
    if np.isnan(z):
        return -np.inf
    return z


@numba.njit(cache=True, inline="always")
def _block_max(bmax, x0, y0, bl, x, y):
    """Conservative surface maximum around (x, y) from a dilated block grid; -inf outside."""
    bc = int(np.floor((x - x0) / bl))
    br = int(np.floor((y0 - y) / bl))
    if 0 <= br < bmax.shape[0] and 0 <= bc < bmax.shape[1]:
        return bmax[br, bc]
    return -np.inf


@numba.njit(cache=True)
def _cast(ox, oy, oz, dx, dy, dz, dsm, x0, y0, cell, bmax, block, smax, sblock, zmin, zmax):
    """Distance along the unit ray to the first surface hit, or -1 if none.

    Rays may descend (kite) or rise (a pole camera below the slope it looks at); the search
    ends where the ray leaves the grid's height range or footprint.

    Empty space is skipped in steps of one super-block and then one block (horizontal
    length) while the ray's lowest point in the step stays above the dilated maximum;
    inside candidate blocks the ray is sampled every cell and the crossing refined by
    the Illinois variant of regula falsi.

    Kept as one function (~200 lines) on purpose: it is the whole compiled numba loop of one
    ray, and splitting it into helper calls adds per-ray call overhead inside the hot loop
    of :func:`_cast_many` (millions of rays per image).
    """
    if dz >= -1e-9 and oz >= zmax:
        return -1.0
    t0 = 0.0
    if oz > zmax:
        t0 = (oz - zmax) / (-dz)
    if dz < -1e-9:
        t1 = (oz - zmin) / (-dz) + 1e-6
    elif dz > 1e-9:  # rising ray from a camera below the highest ground (a pole camera upslope)
        t1 = (zmax - oz) / dz + 1e-6
    else:
        t1 = np.inf
    # leave the grid's footprint: no surface beyond it
    h, w = dsm.shape
    if abs(dx) > 1e-12:
        t1 = min(t1, max((x0 - ox) / dx, (x0 + w * cell - ox) / dx))
    if abs(dy) > 1e-12:
        t1 = min(t1, max((y0 - h * cell - oy) / dy, (y0 - oy) / dy))
    if not t1 > t0:
        return -1.0
    hxy = np.sqrt(dx * dx + dy * dy)
    bl = block * cell
    sbl = sblock * cell
    if hxy > 1e-12:
        seg = bl / hxy
        sseg = sbl / hxy
        fine = cell / hxy
    else:
        seg = t1 - t0
        sseg = t1 - t0
        fine = t1 - t0
    ta = t0
    fa = oz + dz * ta - _height(dsm, x0, y0, cell, ox + dx * ta, oy + dy * ta)
    if fa <= 0.0:
        return ta
    while ta < t1:
        xa = ox + dx * ta
        ya = oy + dy * ta
        tb = min(ta + sseg, t1)
        if oz + dz * tb > _block_max(smax, x0, y0, sbl, xa, ya) and oz + dz * ta > _block_max(smax, x0, y0, sbl, xa, ya):
            ta = tb
            fa = oz + dz * ta - _height(dsm, x0, y0, cell, ox + dx * ta, oy + dy * ta)
            if fa <= 0.0:
                return ta
            continue
        tb = min(ta + seg, t1)
        if oz + dz * tb > _block_max(bmax, x0, y0, bl, xa, ya) and oz + dz * ta > _block_max(bmax, x0, y0, bl, xa, ya):
            ta = tb
            fa = oz + dz * ta - _height(dsm, x0, y0, cell, ox + dx * ta, oy + dy * ta)
            if fa <= 0.0:
                return ta
            continue
        n = max(1, int(np.ceil((tb - ta) / fine)))
        step = (tb - ta) / n
        tp = ta
        fp = fa
        for i in range(1, n + 1):
            tc = ta + i * step
            fc = oz + dz * tc - _height(dsm, x0, y0, cell, ox + dx * tc, oy + dy * tc)
            if fc <= 0.0:
                lo, hi, flo, fhi = tp, tc, fp, fc
                if not np.isfinite(flo):
                    # entering the grid or leaving a hole: bisect to the edge first
                    for _ in range(30):
                        mid = 0.5 * (lo + hi)
                        fm = oz + dz * mid - _height(dsm, x0, y0, cell, ox + dx * mid, oy + dy * mid)
                        if fm <= 0.0:
                            hi, fhi = mid, fm
                        else:
                            lo, flo = mid, fm
                        if np.isfinite(flo) or hi - lo < 1e-4:
                            break
                    if not np.isfinite(flo):
                        return hi
                side = 0
                for _ in range(30):
                    if hi - lo < 1e-5:
                        break
                    mid = lo + (hi - lo) * flo / (flo - fhi)
                    fm = oz + dz * mid - _height(dsm, x0, y0, cell, ox + dx * mid, oy + dy * mid)
                    if abs(fm) < 1e-5:
                        return mid
                    if fm <= 0.0:
                        hi, fhi = mid, fm
                        if side == -1:
                            flo *= 0.5
                        side = -1
                    else:
                        lo, flo = mid, fm
                        if side == 1:
                            fhi *= 0.5
                        side = 1
                return lo + (hi - lo) * flo / (flo - fhi)
            tp, fp = tc, fc
        ta = tb
        fa = fp
    return -1.0


@numba.njit(cache=True, inline="always")
def _tex_level(tex, off, rows, cols, nb, tx0, ty0, tcell, x, y, chans, weight, acc):
    """Add ``weight`` × the bilinear sample of every channel at (x, y) to ``acc``."""
    c = (x - tx0) / tcell - 0.5
    r = (ty0 - y) / tcell - 0.5
    c = min(max(c, 0.0), cols - 1.0)
    r = min(max(r, 0.0), rows - 1.0)
    c0 = min(int(c), cols - 2) if cols > 1 else 0
    r0 = min(int(r), rows - 2) if rows > 1 else 0
    c1 = min(c0 + 1, cols - 1)
    r1 = min(r0 + 1, rows - 1)
    fc = c - c0
    fr = r - r0
    wa = (1 - fc) * (1 - fr) * weight / 255.0
    wb = fc * (1 - fr) * weight / 255.0
    wc = (1 - fc) * fr * weight / 255.0
    wd = fc * fr * weight / 255.0
    ia = off + (r0 * cols + c0) * nb
    ib = off + (r0 * cols + c1) * nb
    ic = off + (r1 * cols + c0) * nb
    idd = off + (r1 * cols + c1) * nb
    for k in range(chans.shape[0]):
        band = chans[k]
        acc[k] += wa * tex[ia + band] + wb * tex[ib + band] + wc * tex[ic + band] + wd * tex[idd + band]


@numba.njit(cache=True, inline="always")
def _sample_tex(tex, offs, shapes, nb, tx0, ty0, tcell, x, y, footprint, chans, acc):
    """Add the trilinear mip-map sample of the channels at (x, y) for a footprint (m) to ``acc``."""
    nl = offs.shape[0]
    lod = np.log2(max(footprint / tcell, 1.0))
    lod = min(lod, nl - 1.0)
    l0 = int(lod)
    fl = lod - l0
    l1 = min(l0 + 1, nl - 1)
    if fl < 1e-3 or l1 == l0:
        _tex_level(tex, offs[l0], shapes[l0, 0], shapes[l0, 1], nb, tx0, ty0, tcell * (1 << l0), x, y, chans, 1.0, acc)
        return
    _tex_level(tex, offs[l0], shapes[l0, 0], shapes[l0, 1], nb, tx0, ty0, tcell * (1 << l0), x, y, chans, 1.0 - fl, acc)
    _tex_level(tex, offs[l1], shapes[l1, 0], shapes[l1, 1], nb, tx0, ty0, tcell * (1 << l1), x, y, chans, fl, acc)


@numba.njit(cache=True, inline="always")
def _undistort(xd, yd, k1, k2):
    xn, yn = xd, yd
    for _ in range(12):
        r2 = xn * xn + yn * yn
        s = 1.0 + k1 * r2 + k2 * r2 * r2
        xn = xd / s
        yn = yd / s
    return xn, yn


@numba.njit(parallel=True, cache=True)
def _render_kernel(
    R, C, f, cx, cy, k1, k2, width, height, ss,
    dsm, x0, y0, cell, bmax, block, smax, sblock, zmin, zmax,
    tex, offs, shapes, nb, tx0, ty0, tcell, chans, background, out, depth,
):
    nc = chans.shape[0]
    inv = 1.0 / ss
    for v in numba.prange(height):
        acc = np.zeros(nc)
        for u in range(width):
            acc[:] = 0.0
            tsum = 0.0
            nhit = 0
            for sj in range(ss):
                for si in range(ss):
                    pu = u - 0.5 + (si + 0.5) * inv
                    pv = v - 0.5 + (sj + 0.5) * inv
                    xn, yn = _undistort((pu - cx) / f, (pv - cy) / f, k1, k2)
                    nrm = np.sqrt(xn * xn + yn * yn + 1.0)
                    a, b, c = xn / nrm, yn / nrm, 1.0 / nrm
                    dx = R[0, 0] * a + R[1, 0] * b + R[2, 0] * c
                    dy = R[0, 1] * a + R[1, 1] * b + R[2, 1] * c
                    dz = R[0, 2] * a + R[1, 2] * b + R[2, 2] * c
                    t = _cast(C[0], C[1], C[2], dx, dy, dz, dsm, x0, y0, cell, bmax, block, smax, sblock, zmin, zmax)
                    if t < 0:
                        for k in range(nc):
                            acc[k] += background[k]
                        continue
                    hx = C[0] + dx * t
                    hy = C[1] + dy * t
                    fp = t * c / (f * ss) / np.sqrt(max(-dz, 0.05))
                    _sample_tex(tex, offs, shapes, nb, tx0, ty0, tcell, hx, hy, fp, chans, acc)
                    tsum += t
                    nhit += 1
            for k in range(nc):
                out[v, u, k] = acc[k] / (ss * ss)
            depth[v, u] = tsum / nhit if nhit > 0 else np.nan


@numba.njit(parallel=True, cache=True)
def _cast_many(O, D, dsm, x0, y0, cell, bmax, block, smax, sblock, zmin, zmax, out):
    for i in numba.prange(O.shape[0]):
        out[i] = _cast(O[i, 0], O[i, 1], O[i, 2], D[i, 0], D[i, 1], D[i, 2], dsm, x0, y0, cell, bmax, block, smax, sblock, zmin, zmax)


# --------------------------------------------------------------------------- public API


def cast_rays(scene: Scene, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Distance (m) along each unit ray to the first surface hit; NaN where none.

    Parameters
    ----------
    scene : Scene
        The surface.
    origins : ndarray (N, 3)
        Ray origins in world coordinates (m).
    directions : ndarray (N, 3)
        Ray directions; normalised here, so any length will do.

    Returns
    -------
    ndarray (N,) float64
        Distance (m) from each origin to the first hit; NaN where the ray hits nothing.
    """
    O = np.ascontiguousarray(np.atleast_2d(origins), dtype=np.float64)
    D = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    D = np.ascontiguousarray(D / np.linalg.norm(D, axis=1, keepdims=True))
    out = np.empty(len(O))
    _cast_many(O, D, *scene.cast_args(), out)
    out[out < 0] = np.nan
    return out


def visible(scene: Scene, pose: Pose, points: np.ndarray, tolerance_m: float) -> np.ndarray:
    """True where the line of sight from the camera centre reaches ``points`` unblocked.

    A point is visible when the first surface hit along the ray towards it lies within
    ``tolerance_m`` of the point's distance (points on the surface) or beyond it.

    Parameters
    ----------
    scene : Scene
        The surface.
    pose : Pose
        Camera pose; only its centre is used.
    points : ndarray (N, 3)
        World points (m).
    tolerance_m : float
        Allowed shortfall of the first hit before the point (m).

    Returns
    -------
    ndarray (N,) bool
        True where the point is visible; also True where the ray hits no surface at all.
    """
    P = np.atleast_2d(np.asarray(points, dtype=float))
    D = P - pose.C
    dist = np.linalg.norm(D, axis=1)
    t = cast_rays(scene, np.repeat(pose.C[None], len(P), axis=0), D)
    return np.isnan(t) | (t >= dist - tolerance_m)


def render_reflectance(
    scene: Scene,
    camera: Camera,
    pose: Pose,
    channels: Sequence[int] = (0, 1, 2),
    supersampling: int = 1,
    background: Sequence[float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast one image.

    Parameters
    ----------
    channels
        Texture band index for each output channel (e.g. ``(0, 1, 2)`` for RGB,
        ``(3, 3, 3)`` for an NIR-converted camera).
    supersampling
        ``s`` gives ``s × s`` stratified rays per pixel (antialiased occlusion edges).
    background
        Reflectance (0–1) per output channel where a ray misses the surface.

    Returns
    -------
    reflectance : (height, width, channels) float32 in 0–1
    depth : (height, width) float32 distance (m) along the ray, NaN where nothing was hit
    """
    chans = np.asarray(channels, dtype=np.int64)
    if chans.min() < 0 or chans.max() >= scene.nbands:
        raise ValueError(f"channel index out of range for a {scene.nbands}-band texture: {list(channels)}")
    bg = np.asarray(background if background is not None else [0.0] * len(chans), dtype=np.float64)
    out = np.empty((camera.height, camera.width, len(chans)), dtype=np.float32)
    depth = np.empty((camera.height, camera.width), dtype=np.float32)
    _render_kernel(
        np.ascontiguousarray(pose.R, dtype=np.float64), np.asarray(pose.C, dtype=np.float64),
        camera.f, camera.cx, camera.cy, camera.k1, camera.k2, camera.width, camera.height, int(supersampling),
        *scene.cast_args(),
        scene.tex, scene.tex_offsets, scene.tex_shapes, scene.nbands, scene.tex_x0, scene.tex_y0, scene.tex_cell,
        chans, bg, out, depth,
    )
    return out, depth


# --------------------------------------------------------------------------- camera effects


@dataclass(frozen=True)
class Photographic:
    """Camera effects applied after ray casting (see the ``flight.render`` config section).

    Attributes
    ----------
    exposure_gain : float
        Scene-linear gain mapping reflectance to sensor signal (1 = white saturates).
    exposure_ev_sd : float
        Standard deviation (EV, stops) of the shot-to-shot exposure variation.
    vignetting : float
        Relative light fall-off at the image corner, ``1 − vignetting·(r/r_corner)²``.
    gamma : float
        Display gamma of the tone curve (``DN = 255·signal^(1/gamma)``).
    read_noise_dn, shot_noise_dn2_per_dn : float
        Sensor noise: ``σ² = read² + shot·DN`` in 8-bit units.
    exposure_time_s : float
        Shutter time; with the camera's motion gives the motion-blur length.
    """

    exposure_gain: float = 1.6
    exposure_ev_sd: float = 0.15
    vignetting: float = 0.25
    gamma: float = 2.2
    read_noise_dn: float = 1.0
    shot_noise_dn2_per_dn: float = 0.05
    exposure_time_s: float = 0.002

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "Photographic":
        """Build from a config mapping holding every attribute's key (read as float; other keys ignored)."""
        return cls(**{k: float(cfg[k]) for k in cls.__dataclass_fields__})


def motion_kernel(blur_px: np.ndarray) -> np.ndarray | None:
    """Normalised line kernel for an image-space blur vector (px); None below 0.3 px."""
    length = float(np.hypot(*blur_px))
    if length < 0.3:
        return None
    half = int(np.ceil(length / 2)) + 1
    size = 2 * half + 1
    k = np.zeros((size, size), dtype=np.float32)
    n = max(8, int(np.ceil(length * 4)))
    for s in np.linspace(-0.5, 0.5, n):
        x, y = half + s * blur_px[0], half + s * blur_px[1]
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        k[y0, x0] += (1 - fx) * (1 - fy)
        k[y0, x0 + 1] += fx * (1 - fy)
        k[y0 + 1, x0] += (1 - fx) * fy
        k[y0 + 1, x0 + 1] += fx * fy
    return k / k.sum()


def photograph(
    reflectance: np.ndarray,
    camera: Camera,
    effects: Photographic,
    rng: np.random.Generator,
    blur_px: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Turn rendered reflectance into an 8-bit photograph.

    Order: exposure (random EV offset) → vignetting → motion blur → tone curve →
    sensor noise → quantisation. Vectorised; O(pixels).

    Parameters
    ----------
    reflectance : ndarray (height, width, channels) float32
        Rendered reflectance (0–1), as from :func:`render_reflectance`.
    camera : Camera
        The camera; its principal point centres the vignetting.
    effects : Photographic
        Exposure, vignetting, tone curve and noise settings.
    rng : numpy.random.Generator
        Random stream for the exposure offset and the sensor noise.
    blur_px : ndarray (2,) or None
        Motion-blur vector in the image (px); None or shorter than 0.3 px gives no blur.

    Returns
    -------
    image : (height, width, channels) uint8
    ev_offset : float
        The exposure offset (stops) drawn for this shot.
    """
    ev = float(rng.normal(0.0, effects.exposure_ev_sd)) if effects.exposure_ev_sd > 0 else 0.0
    gain = effects.exposure_gain * 2.0**ev
    h, w = reflectance.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xx - camera.cx) ** 2 + (yy - camera.cy) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    vig = (1.0 - effects.vignetting * r2).astype(np.float32)
    signal = reflectance * (gain * vig)[..., None]
    if blur_px is not None:
        k = motion_kernel(np.asarray(blur_px, dtype=float))
        if k is not None:
            signal = cv2.filter2D(signal, -1, k, borderType=cv2.BORDER_REFLECT)
            if signal.ndim == 2:
                signal = signal[..., None]
    dn = 255.0 * np.clip(signal, 0.0, 1.0) ** (1.0 / effects.gamma)
    sigma = np.sqrt(effects.read_noise_dn**2 + effects.shot_noise_dn2_per_dn * dn)
    dn = dn + sigma * rng.standard_normal(dn.shape, dtype=np.float32)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8), ev


@numba.njit(parallel=True, cache=True)
def _heights(dsm, x0, y0, cell, x, y, out):
    for i in numba.prange(x.shape[0]):
        out[i] = _height(dsm, x0, y0, cell, x[i], y[i])


def surface_height(scene: Scene, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear surface height at map points (NaN outside the DSM), as the ray caster sees it.

    Parameters
    ----------
    scene : Scene
        The surface.
    x, y : ndarray
        Map coordinates (m); flattened.

    Returns
    -------
    ndarray (N,) float64
        Surface height (m) per point; NaN outside the DSM or next to a NaN cell.
    """
    x = np.ascontiguousarray(np.ravel(x), dtype=np.float64)
    y = np.ascontiguousarray(np.ravel(y), dtype=np.float64)
    out = np.empty(len(x))
    _heights(scene.dsm, scene.x0, scene.y0, scene.cell, x, y, out)
    out[~np.isfinite(out)] = np.nan
    return out
