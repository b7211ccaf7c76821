"""A DEM twin like Höfle et al.'s (2013) site: one branching gully system in a peat valley.

The paper mapped one gully system cut into a nearly level cushion peatland (widths
3.5–51 m, maximum depths 2.4–7.5 m, 6 919–8 773 m² of gully) from a TLS DTM at 0.5 m. This
twin builds such a DTM with known gullies; the site is surveyed as a dense DTM only (no
photographs), and the polygons stage runs on it as on any DEM site:

- plateau: 1 % down-valley, rising 2 % to the valley sides, smooth micro-relief of SD 0.1 m;
- gullies (carved exactly as the Kamech twin carves, :func:`kitegully.twin.gullies.carve`):
  a meandering main channel widening from 8 to 45 m and deepening from 2.4 to 6 m, U-shaped,
  with three tributaries 3.5–10 m wide and 2.4–3.5 m deep;
- TLS-like survey: white noise (the paper's registration SD 0.034 m) and about 3 % of the
  cells empty in small clusters (occlusion), left as NaN for the stage's moving planes.

Entry point: :func:`make_peat_valley` with :class:`PeatValleyParams` (``dem_twin:`` section).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import geopandas as gpd
import numpy as np
import scipy.ndimage as ndi

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import GridSpec, Raster
from kitegully.seeds import rng_for
from kitegully.twin.gullies import Gully, Segments, carve
from kitegully.twin.gully_truth import centrelines, polygons

#: Kinds of DEM twin (``dem_twin.kind``).
KINDS = ("peat_valley",)


@dataclass(frozen=True)
class PeatValleyParams:
    """The ``dem_twin:`` section.

    Attributes
    ----------
    kind : str
        ``peat_valley`` (:data:`KINDS`).
    x0, y0 : float
        Upper-left corner of the DTM in the site CRS (m).
    width_m, height_m : float
        Extent (m): 400 × 240 m holds the paper's ~8 000 m² gully system with its valley.
    cell_m : float
        DTM cell (m) [P 0.5 m, the paper's DTM].
    noise_sd_m : float
        White noise of the survey (m) [P 0.034 m, the TLS registration SD].
    occlusion_sd : float
        Cells where a smoothed (σ 1.5 cells) Gaussian field exceeds this many of its SDs are
        empty [I 2.0: about 3 % of the cells in clusters of a few cells, TLS shadows behind
        the rims].
    u_shape_exponent : float
        U profile ``D (1 − |d/h|^p)`` of the gullies [I 4, a flat peat floor].
    """

    kind: str = "peat_valley"
    x0: float = 500000.0
    y0: float = 8430000.0
    width_m: float = 400.0
    height_m: float = 240.0
    cell_m: float = 0.5
    noise_sd_m: float = 0.034
    occlusion_sd: float = 2.0
    u_shape_exponent: float = 4.0

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "PeatValleyParams":
        """Build from the ``dem_twin:`` section (keys as in ``dem_twin.schema.yaml``)."""
        c = config_section(cfg, "dem_twin", ["kind", "x0", "y0", "width_m", "height_m", "cell_m", "noise_sd_m", "occlusion_sd", "u_shape_exponent"])
        return cls(kind=c["kind"], x0=float(c["x0"]), y0=float(c["y0"]), width_m=float(c["width_m"]), height_m=float(c["height_m"]),
                   cell_m=float(c["cell_m"]), noise_sd_m=float(c["noise_sd_m"]), occlusion_sd=float(c["occlusion_sd"]),
                   u_shape_exponent=float(c["u_shape_exponent"]))

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InputError(f"dem_twin.kind: must be one of {KINDS}, got {self.kind!r}")
        if self.width_m < 400.0 or self.height_m < 240.0:
            raise InputError(f"dem_twin.width_m/height_m: the peat valley's gullies need at least 400 x 240 m, got {self.width_m} x {self.height_m}")


@dataclass
class PeatValley:
    """Products of :func:`make_peat_valley`."""

    observed: Raster  # the TLS-like DTM (noise, NaN = occluded)
    truth: Raster  # the noise-free DTM
    gullies: list[Gully]
    centrelines: gpd.GeoDataFrame
    polygons: gpd.GeoDataFrame


def make_peat_valley(params: PeatValleyParams, seed: int, crs: str) -> PeatValley:
    """Build the peat-valley DTM and its true gullies.

    Parameters
    ----------
    params : PeatValleyParams
    seed : int
        Site seed (streams ``rng_for(seed, "twin", "peat_valley")``).
    crs : str
        Site CRS (metres).

    Returns
    -------
    PeatValley

    Notes
    -----
    O(cells × gully segments near each cell) for the carving; ~1 s for 400 × 240 m at 0.5 m.
    """
    p = params
    rng = rng_for(seed, "twin", "peat_valley")
    W, H, cell = p.width_m, p.height_m, p.cell_m
    grid = GridSpec(p.x0, p.y0, cell, int(round(W / cell)), int(round(H / cell)), crs)
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs - grid.x0, ys - (grid.y0 - H))
    z = 4400.0 - 0.01 * x + 0.02 * np.abs(y - H / 2)  # 1 % down-valley, 2 % up to the valley sides
    noise = ndi.gaussian_filter(rng.standard_normal(x.shape), 5.0 / cell)
    z += 0.1 * noise / noise.std()
    # main channel west to east, meandering, widening and deepening downstream
    s = np.arange(0.0, 400.0 + 1.0, 1.0)
    mx = grid.x0 + s
    my = grid.y0 - H / 2 + 25.0 * np.sin(2 * np.pi * s / 260.0)
    t = s / s[-1]
    main = Gully(0, "wadi", "valley", "U", mx, my, width=8.0 + 37.0 * t**1.5, depth=2.4 + 3.6 * t)
    gullies = [main]
    for k, (s0, side, L) in enumerate(((90.0, 1, 70.0), (190.0, -1, 80.0), (290.0, 1, 60.0)), start=1):
        j = int(s0)
        ang = np.arctan2(my[j + 1] - my[j - 1], mx[j + 1] - mx[j - 1]) + side * np.radians(120.0)
        u = np.arange(L, -1.0, -1.0)  # head first
        tx = mx[j] + u * np.cos(ang)
        ty = my[j] + u * np.sin(ang) + 4.0 * np.sin(u / 15.0)
        tt = 1.0 - u / L
        w = 3.5 + (6.5 * tt if k != 2 else 6.5 * tt**0.5)
        d = 2.4 + 1.1 * tt
        gullies.append(Gully(k, "gully", "left" if side < 0 else "right", "U", tx, ty, joins=0, join_index=j, width=w, depth=d))
    segs = Segments.from_network(gullies, p.u_shape_exponent)
    depth, _ = carve(segs, grid, 2.0)
    truth = (z - depth).astype(np.float32)
    obs = truth + rng.normal(0.0, p.noise_sd_m, truth.shape).astype(np.float32)
    f = ndi.gaussian_filter(rng.standard_normal(truth.shape), 1.5)
    obs[f > p.occlusion_sd * f.std()] = np.nan
    return PeatValley(Raster(obs, grid, np.nan), Raster(truth, grid, np.nan), gullies,
                      centrelines(gullies, 0.1, 10.0, crs), polygons(gullies, 0.1, crs))
