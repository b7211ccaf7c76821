"""Gully network with known geometry: heads at field edges, streamline tracing, carving.

1. Heads are drawn on row boundaries of the field layout (gully heads sit at field edges,
   Feurer et al. 2018 sect. 2.1), more densely on the right bank, at a minimum spacing.
2. From each head, highest first, a streamline follows the steepest descent of the smooth
   pre-gully surface (micro-relief above ``trace_min_wavelength_m``) until it reaches the
   main wadi, the reservoir, an earlier gully (a confluence), a flat, or the site edge.
3. Width and depth grow with the upstream channel length (own length plus tributaries);
   shallow, weakly incised gullies on the left bank; V (p = 1) or U (p = 4) sections; a
   sharp headcut or a tapering head; a few discontinuous reaches where depth falls to 0.
4. Carving is exact per segment: the depth removed at a cell is the maximum over all
   segments of ``D·(1 − (d/h)^p)`` for distance d < half-width h (compiled kernel).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for
from kitegully.twin.landcover import Fields
from kitegully.twin.terrain import Valley


@dataclass
class Gully:
    """One traced channel; vertex arrays run from the head downstream."""

    gully_id: int
    kind: str  # "wadi", "gully" or "shallow"
    bank: str  # "right", "left" or "valley"
    shape: str  # "V" or "U"
    x: np.ndarray
    y: np.ndarray
    headcut: bool = False
    joins: int = -1  # gully id this one flows into (-1: none, 0: the wadi/reservoir)
    join_index: int = -1  # vertex index on the receiving gully
    end_reason: str = ""
    width: np.ndarray = field(default_factory=lambda: np.zeros(0))
    depth: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upstream_length: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def s(self) -> np.ndarray:
        """Distance from the head along the centreline (m)."""
        return np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(self.x), np.diff(self.y)))])

    @property
    def length(self) -> float:
        """Centreline length from the head to the last vertex (m); 0 with fewer than two vertices."""
        return float(self.s[-1]) if len(self.x) > 1 else 0.0


# ----------------------------------------------------------------------------- tracing
@njit(cache=True)
def _bilinear(a, r, c):
    nr, nc = a.shape
    r = min(max(r, 0.0), nr - 1.000001)
    c = min(max(c, 0.0), nc - 1.000001)
    r0 = int(r)
    c0 = int(c)
    fr = r - r0
    fc = c - c0
    return (a[r0, c0] * (1 - fr) * (1 - fc) + a[r0, c0 + 1] * (1 - fr) * fc
            + a[r0 + 1, c0] * fr * (1 - fc) + a[r0 + 1, c0 + 1] * fr * fc)


@njit(cache=True)
def _trace(gx, gy, occ, x0, y0, cell, hx, hy, step, max_steps, self_id, min_grad):
    """Streamline of steepest descent from (hx, hy). Returns xs, ys, n, joined id, reason code."""
    xs = np.empty(max_steps + 1)
    ys = np.empty(max_steps + 1)
    nr, nc = occ.shape
    x = hx
    y = hy
    for k in range(max_steps):
        xs[k] = x
        ys[k] = y
        c = (x - x0) / cell - 0.5
        r = (y0 - y) / cell - 0.5
        if r < 0 or c < 0 or r > nr - 1 or c > nc - 1:
            return xs, ys, k, -1, 1  # left the site (this vertex is outside: dropped)
        o = occ[int(r + 0.5), int(c + 0.5)]
        if k > 0 and o >= 0 and o != self_id:
            return xs, ys, k + 1, o, 2
        dzdx = _bilinear(gx, r, c)
        dzdy = _bilinear(gy, r, c)
        g = np.sqrt(dzdx * dzdx + dzdy * dzdy)
        if g < min_grad:
            return xs, ys, k + 1, -1, 3
        if k >= 2:
            # stuck in a pit: oscillating back and forth
            if (x - xs[k - 2]) ** 2 + (y - ys[k - 2]) ** 2 < (0.25 * step) ** 2:
                return xs, ys, k + 1, -1, 3
        x = x - step * dzdx / g
        y = y - step * dzdy / g
    return xs, ys, max_steps, -1, 4


@njit(cache=True)
def _mark(occ, x0, y0, cell, xs, ys, radius, gid):
    nr, nc = occ.shape
    rad = int(np.ceil(radius / cell))
    for i in range(xs.size):
        c = (xs[i] - x0) / cell - 0.5
        r = (y0 - ys[i]) / cell - 0.5
        ci = int(np.round(c))
        ri = int(np.round(r))
        for dr in range(-rad, rad + 1):
            rr = ri + dr
            if rr < 0 or rr >= nr:
                continue
            for dc in range(-rad, rad + 1):
                cc = ci + dc
                if cc < 0 or cc >= nc:
                    continue
                if (dr * dr + dc * dc) * cell * cell <= radius * radius and occ[rr, cc] < 0:
                    occ[rr, cc] = gid


_REASONS = {1: "edge", 2: "confluence", 3: "depression", 4: "max_length"}


# ------------------------------------------------------------------------------ heads
def sample_heads(
    valley: Valley, fields: Fields, gcfg: dict, bounds: tuple[float, float, float, float], z_trace: np.ndarray,
    tgrid: GridSpec, occ: np.ndarray, seed: int,
) -> list[tuple[float, float, str]]:
    """Gully heads on field-row boundaries, Poisson-disc thinned; returns (x, y, bank).

    Parameters
    ----------
    valley : Valley
        The valley.
    fields : Fields
        The field layout; heads sit on its row boundaries.
    gcfg : mapping
        ``twin.gullies``; reads ``heads_per_km2`` (per bank), ``head_edge_margin_m`` (m),
        ``head_min_height_above_lake_m`` (m) and ``min_head_spacing_m`` (m).
    bounds : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).
    z_trace : ndarray
        Pre-gully surface (m) on ``tgrid``.
    tgrid : GridSpec
        The tracing grid.
    occ : ndarray of int
        Occupancy on ``tgrid`` (−1 free); heads lie on free cells only.
    seed : int
        Master seed.

    Returns
    -------
    list of tuple (float, float, str)
        ``(x, y, bank)`` per head (m; bank ``"right"`` or ``"left"``).
    """
    xmin, ymin, xmax, ymax = bounds
    margin = gcfg["head_edge_margin_m"]
    rng = rng_for(seed, "twin", "gully_heads")
    heads: list[tuple[float, float, str]] = []
    pts = np.zeros((0, 2))
    area_km2 = (xmax - xmin) * (ymax - ymin) / 1e6
    for bank, sign in (("right", 1), ("left", -1)):
        n_want = int(round(gcfg["heads_per_km2"][bank] * area_km2))
        if n_want == 0:
            continue
        n_cand = 40 * n_want + 200
        # farthest distance up the bank inside the site
        a_max = max(abs(valley.uv(x, y)[1] - valley.axis_offset) for x in (xmin, xmax) for y in (ymin, ymax))
        k_max = int(a_max / fields.row_depth) + 1
        k = rng.integers(0, k_max + 1, n_cand)
        u = rng.uniform(valley.u_min, valley.u_dam, n_cand)
        a = fields.row_boundary(sign, k)
        vp = sign * (valley.floor_half_width + fields.floor_margin + a)
        x, y = valley.xy(u, vp + valley.axis_v(u))
        ok = (x > xmin + margin) & (x < xmax - margin) & (y > ymin + margin) & (y < ymax - margin)
        r, c = tgrid.rowcol(x, y)
        ri = np.clip(np.round(r).astype(int), 0, occ.shape[0] - 1)
        ci = np.clip(np.round(c).astype(int), 0, occ.shape[1] - 1)
        ok &= occ[ri, ci] < 0
        ok &= z_trace[ri, ci] > valley.water_level + gcfg["head_min_height_above_lake_m"]
        n_got = 0
        for xi, yi in zip(x[ok], y[ok]):
            if n_got >= n_want:
                break
            if len(pts) and np.min(np.hypot(pts[:, 0] - xi, pts[:, 1] - yi)) < gcfg["min_head_spacing_m"]:
                continue
            pts = np.vstack([pts, [xi, yi]])
            heads.append((float(xi), float(yi), bank))
            n_got += 1
    return heads


# ---------------------------------------------------------------------------- network
def wadi_centreline(
    valley: Valley, bounds: tuple[float, float, float, float], step: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The main wadi along the valley axis, from the upstream site edge to the dam.

    Parameters
    ----------
    valley : Valley
        The valley.
    bounds : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).
    step : float
        Vertex spacing along the valley (m).

    Returns
    -------
    x, y : ndarray
        Vertices (m) within 20 m of the site, from upstream down.
    """
    xmin, ymin, xmax, ymax = bounds
    u = np.arange(valley.u_min - 50.0, valley.u_dam - 0.5 * valley.dam_crest_width, step)
    x, y = valley.xy(u, valley.axis_v(u))
    pad = 20.0
    inside = (x > xmin - pad) & (x < xmax + pad) & (y > ymin - pad) & (y < ymax + pad)
    return x[inside], y[inside]


def plan_network(
    valley: Valley, fields: Fields, gcfg: dict, bounds: tuple[float, float, float, float], z_trace: np.ndarray,
    tgrid: GridSpec, seed: int,
) -> list[Gully]:
    """The twin's true network: wadi plus gullies traced from sampled heads on the
    pre-gully surface ``z_trace`` (not :func:`kitegully.gully.network.trace_network`,
    which traces a network on an observed DEM).

    Complexity O(heads·max_steps) for tracing plus O(cells) for the gradient.

    Parameters
    ----------
    valley : Valley
        The valley.
    fields : Fields
        The field layout.
    gcfg : mapping
        ``twin.gullies``: head, tracing, joining and wadi keys.
    bounds : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).
    z_trace : ndarray
        Pre-gully surface (m) on ``tgrid``.
    tgrid : GridSpec
        The tracing grid.
    seed : int
        Master seed.

    Returns
    -------
    list of Gully
        The wadi (id 0) first, then the gullies in tracing order; widths and depths not yet set
        (:func:`assign_attributes`).
    """
    cell = tgrid.cell
    gy_r, gx = np.gradient(z_trace, cell)
    gy = -gy_r  # rows go south
    occ = np.full(z_trace.shape, -1, dtype=np.int32)
    step = gcfg["trace_step_m"]
    w = gcfg["wadi"]
    wx, wy = wadi_centreline(valley, bounds, step)
    wadi = Gully(0, "wadi", "valley", "U", wx, wy, headcut=False, end_reason="reservoir")
    wadi_radius = 0.5 * max(w["width_upstream_m"], w["width_outlet_m"]) + gcfg["join_radius_m"]
    _mark(occ, tgrid.x0, tgrid.y0, cell, wx, wy, wadi_radius, 0)
    xs, ys = tgrid.cell_centres()
    u, _ = valley.uv(xs[None, :], ys[:, None])
    occ[(z_trace < valley.water_level) & valley.lake_zone(u)] = 0
    heads = sample_heads(valley, fields, gcfg, bounds, z_trace, tgrid, occ, seed)
    r, c = tgrid.rowcol(np.array([h[0] for h in heads]), np.array([h[1] for h in heads])) if heads else (np.zeros(0), np.zeros(0))
    zh = z_trace[np.clip(np.round(r).astype(int), 0, z_trace.shape[0] - 1), np.clip(np.round(c).astype(int), 0, z_trace.shape[1] - 1)] if heads else np.zeros(0)
    order = np.argsort(-zh, kind="stable")
    gullies = [wadi]
    max_steps = int(gcfg["max_length_m"] / step)
    for i in order:
        hx, hy, bank = heads[i]
        gid = len(gullies)
        ri, ci = tgrid.rowcol(hx, hy)
        if occ[int(round(float(ri))), int(round(float(ci)))] >= 0:
            continue
        xs_t, ys_t, n, joined, reason = _trace(gx, gy, occ, tgrid.x0, tgrid.y0, cell, hx, hy, step, max_steps, gid, gcfg["min_gradient"])
        if n < 2:
            continue
        xs_g, ys_g = xs_t[:n].copy(), ys_t[:n].copy()
        if reason == 3:
            xs_g, ys_g, joined, reason = _extend_to_wadi(valley, fields, gcfg, occ, tgrid, xs_g, ys_g, step)
        join_index = -1
        if joined >= 0:
            # the trace stops where it enters the receiving channel's occupancy zone; run
            # the centreline on to that channel's centreline so the confluence is a shared node
            tgt = gullies[joined]
            join_index = int(np.argmin(np.hypot(tgt.x - xs_g[-1], tgt.y - ys_g[-1])))
            reach = wadi_radius if joined == 0 else gcfg["join_radius_m"]
            xs_g, ys_g = _bridge(xs_g, ys_g, tgt.x[join_index], tgt.y[join_index], step, reach + 2 * step)
        g = Gully(gid, "gully", bank, "V", xs_g, ys_g, joins=int(joined), end_reason=_REASONS[int(reason)])
        if g.length < gcfg["min_length_m"]:
            continue
        if joined >= 0:
            g.join_index = join_index
        _mark(occ, tgrid.x0, tgrid.y0, cell, g.x, g.y, gcfg["join_radius_m"], gid)
        gullies.append(g)
    return gullies


def _bridge(xs, ys, tx, ty, step, max_dist):
    """Append a straight run from the last vertex to (tx, ty) when it is within ``max_dist``.

    A trace that stopped at the edge of the reservoir (far from the wadi axis) is left as is.
    """
    d = float(np.hypot(tx - xs[-1], ty - ys[-1]))
    if d < 1e-9 or d > max_dist:
        return xs, ys
    k = np.arange(1, int(np.ceil(d / step)) + 1) / np.ceil(d / step)
    return np.concatenate([xs, xs[-1] + k * (tx - xs[-1])]), np.concatenate([ys, ys[-1] + k * (ty - ys[-1])])


def _extend_to_wadi(valley, fields, gcfg, occ, tgrid, xs, ys, step):
    """A streamline stuck in a depression of the valley floor runs straight across the floor to the wadi."""
    _, vp = valley.u_vp(xs[-1], ys[-1])
    if abs(vp) > valley.floor_half_width + fields.floor_margin + gcfg["floor_extension_m"]:
        return xs, ys, -1, 3
    rx, ry = valley.right
    sgn = -np.sign(vp) if vp != 0 else 1.0
    n = int((abs(vp) + 5.0) / step)
    k = np.arange(1, n + 1) * step
    ex, ey = xs[-1] + sgn * rx * k, ys[-1] + sgn * ry * k
    r, c = tgrid.rowcol(ex, ey)
    ri = np.clip(np.round(r).astype(int), 0, occ.shape[0] - 1)
    ci = np.clip(np.round(c).astype(int), 0, occ.shape[1] - 1)
    hit = np.nonzero(occ[ri, ci] == 0)[0]
    if not len(hit):
        return xs, ys, -1, 3
    m = hit[0] + 1
    return np.concatenate([xs, ex[:m]]), np.concatenate([ys, ey[:m]]), 0, 2


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def assign_attributes(gullies: list[Gully], gcfg: dict, valley: Valley, seed: int, widen: dict | None = None) -> None:
    """Width, depth and section shape per vertex (in place).

    ``widen`` maps gully id → (width factor, depth increment) for the second epoch.
    Random draws are keyed by gully id so both epochs share them.

    Parameters
    ----------
    gullies : list of Gully
        The network, as from :func:`plan_network`; updated in place.
    gcfg : mapping
        ``twin.gullies``: wadi, bank, shallow, shape, headcut, taper and discontinuity keys.
    valley : Valley
        The valley; the wadi's width and depth change linearly from its upstream end to the dam.
    seed : int
        Master seed.
    widen : dict or None
        Width factor and depth increment (m) per gully id; None for epoch 1.
    """
    # upstream channel length, tributaries first (they were traced later: reverse order)
    for g in gullies:
        g.upstream_length = g.s.copy()
    by_id = {g.gully_id: g for g in gullies}
    for g in reversed(gullies):
        if g.joins > 0 and g.joins in by_id:
            tgt = by_id[g.joins]
            tgt.upstream_length[g.join_index:] += g.upstream_length[-1]
    w = gcfg["wadi"]
    for g in gullies:
        rng = rng_for(seed, "twin", "gully_attr", str(g.gully_id))
        if g.kind == "wadi":
            uu, _ = valley.uv(g.x, g.y)
            t = np.clip((uu - valley.u_min) / max(valley.u_dam - valley.u_min, 1.0), 0.0, 1.0)
            g.width = w["width_upstream_m"] + t * (w["width_outlet_m"] - w["width_upstream_m"])
            g.depth = w["depth_upstream_m"] + t * (w["depth_outlet_m"] - w["depth_upstream_m"])
            g.shape = "U"
        else:
            b = gcfg[g.bank]
            draws = rng.uniform(size=10)
            shallow = g.bank == "left" and draws[0] < gcfg["shallow_share_left"]
            g.kind = "shallow" if shallow else "gully"
            g.shape = "U" if draws[1] < gcfg["u_shape_share"] else "V"
            g.headcut = bool(draws[2] < gcfg["headcut_share"]) and not shallow
            lo_hi = lambda r, q: r[0] + q * (r[1] - r[0])  # noqa: E731
            if shallow:
                wh = lo_hi(gcfg["shallow_width_m"], draws[3])
                wm = wh
                dh = lo_hi(gcfg["shallow_depth_m"], draws[4])
                dm = dh
            else:
                wh = lo_hi(b["head_width_m"], draws[3])
                wm = max(wh, lo_hi(b["max_width_m"], draws[5]))
                dh = lo_hi(b["head_depth_m"], draws[4])
                dm = max(dh, lo_hi(b["max_depth_m"], draws[6]))
            grow = 1.0 - np.exp(-g.upstream_length / gcfg["growth_length_m"])
            width = wh + (wm - wh) * grow
            depth = dh + (dm - dh) * grow
            s = g.s
            ramp = gcfg["headcut_length_m"] if g.headcut else gcfg["taper_length_m"]
            depth = depth * _smoothstep(s / ramp)
            if not g.headcut:
                width = width * (0.3 + 0.7 * _smoothstep(s / ramp))
            if draws[7] < gcfg["discontinuous_share"] and g.length > 3 * gcfg["discontinuous_length_m"][1]:
                ln = lo_hi(gcfg["discontinuous_length_m"], draws[8])
                s0 = (0.3 + 0.4 * draws[9]) * g.length
                # depth falls to zero over a gap of length ln, with 3 m transitions either side
                gap = _smoothstep((np.abs(s - s0 - 0.5 * ln) - 0.5 * ln) / 3.0)
                depth = depth * gap
            g.width = width
            g.depth = depth
        if widen is not None and g.gully_id in widen:
            fw, dd = widen[g.gully_id]
            g.width = g.width * fw
            g.depth = np.where(g.depth > 0, g.depth + dd, 0.0)


# ---------------------------------------------------------------------------- carving
@dataclass
class Segments:
    """All centreline segments as flat arrays for the carving kernel."""

    x0: np.ndarray
    y0: np.ndarray
    x1: np.ndarray
    y1: np.ndarray
    h0: np.ndarray
    h1: np.ndarray
    d0: np.ndarray
    d1: np.ndarray
    p: np.ndarray
    gid: np.ndarray

    @classmethod
    def from_network(cls, gullies: list[Gully], u_exponent: float) -> "Segments":
        """The centreline segments of every gully (gullies with fewer than two vertices skipped).

        Parameters
        ----------
        gullies : list of Gully
            Traced gullies with ``width`` and ``depth`` (m) at each vertex.
        u_exponent : float
            Cross-section exponent ``p`` of U-shaped gullies; V-shaped ones take 1.

        Returns
        -------
        Segments
            Per segment: end points, half-widths ``h0, h1`` and depths ``d0, d1`` (m) at its ends,
            exponent ``p`` and gully id.
        """
        parts = []
        for g in gullies:
            if len(g.x) < 2:
                continue
            n = len(g.x) - 1
            pexp = u_exponent if g.shape == "U" else 1.0
            parts.append((g.x[:-1], g.y[:-1], g.x[1:], g.y[1:], 0.5 * g.width[:-1], 0.5 * g.width[1:],
                          g.depth[:-1], g.depth[1:], np.full(n, pexp), np.full(n, g.gully_id)))
        cols = [np.concatenate([p[i] for p in parts]) if parts else np.zeros(0) for i in range(10)]
        return cls(*[np.ascontiguousarray(c, np.float64) for c in cols[:9]], gid=cols[9].astype(np.int64))

    def select(self, bounds: tuple[float, float, float, float], buffer: float) -> "Segments":
        """Segments whose influence (half-width + buffer) reaches into ``bounds``."""
        xmin, ymin, xmax, ymax = bounds
        h = np.maximum(self.h0, self.h1) + buffer
        keep = ((np.maximum(self.x0, self.x1) + h >= xmin) & (np.minimum(self.x0, self.x1) - h <= xmax)
                & (np.maximum(self.y0, self.y1) + h >= ymin) & (np.minimum(self.y0, self.y1) - h <= ymax))
        return Segments(*[getattr(self, f)[keep] for f in ("x0", "y0", "x1", "y1", "h0", "h1", "d0", "d1", "p", "gid")])


@njit(cache=True)
def _carve(x0g, y0g, cell, nr, nc, sx0, sy0, sx1, sy1, h0, h1, d0, d1, pexp, buf, depth, rim):
    for s in range(sx0.size):
        hmax = max(h0[s], h1[s]) + buf
        cmin = int(np.floor((min(sx0[s], sx1[s]) - hmax - x0g) / cell))
        cmax = int(np.ceil((max(sx0[s], sx1[s]) + hmax - x0g) / cell))
        rmin = int(np.floor((y0g - max(sy0[s], sy1[s]) - hmax) / cell))
        rmax = int(np.ceil((y0g - min(sy0[s], sy1[s]) + hmax) / cell))
        cmin = max(cmin, 0)
        rmin = max(rmin, 0)
        cmax = min(cmax, nc - 1)
        rmax = min(rmax, nr - 1)
        dx = sx1[s] - sx0[s]
        dy = sy1[s] - sy0[s]
        l2 = dx * dx + dy * dy
        for r in range(rmin, rmax + 1):
            y = y0g - (r + 0.5) * cell
            for c in range(cmin, cmax + 1):
                x = x0g + (c + 0.5) * cell
                t = 0.0
                if l2 > 0:
                    t = ((x - sx0[s]) * dx + (y - sy0[s]) * dy) / l2
                    t = min(max(t, 0.0), 1.0)
                px = sx0[s] + t * dx - x
                py = sy0[s] + t * dy - y
                d = np.sqrt(px * px + py * py)
                h = h0[s] + t * (h1[s] - h0[s])
                e = d - h
                if e < rim[r, c]:
                    rim[r, c] = e
                if d < h:
                    dd = d0[s] + t * (d1[s] - d0[s])
                    v = dd * (1.0 - (d / h) ** pexp[s])
                    if v > depth[r, c]:
                        depth[r, c] = v


def carve(segs: Segments, grid: GridSpec, buffer: float) -> tuple[np.ndarray, np.ndarray]:
    """Gully depth (m, ≥ 0) and distance outside the nearest rim (m; < 0 inside) on ``grid``.

    The rim distance is only exact within ``buffer`` of a gully (``+inf`` beyond).
    Complexity O(Σ segment bounding-box cells).

    Parameters
    ----------
    segs : Segments
        Centreline segments of the network.
    grid : GridSpec
        The grid (or a tile of it).
    buffer : float
        Distance beyond the rim within which the rim distance is computed (m).

    Returns
    -------
    depth, rim : ndarray (rows, cols) float64
        Depth (m) and distance outside the nearest rim (m) per cell.
    """
    nrow, ncol = grid.shape
    depth = np.zeros((nrow, ncol), dtype=np.float64)
    rim = np.full((nrow, ncol), np.inf, dtype=np.float64)
    s = segs.select(grid.bounds, buffer)
    if s.x0.size:
        _carve(float(grid.x0), float(grid.y0), float(grid.cell), nrow, ncol, s.x0, s.y0, s.x1, s.y1, s.h0, s.h1, s.d0, s.d1, s.p, float(buffer), depth, rim)
    return depth, rim
