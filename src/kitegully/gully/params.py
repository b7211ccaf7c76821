"""Method parameters of the gully-mapping chain (the ``gully:`` config section)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from kitegully import InputError
from kitegully.gully.crowns import CrownParams
from kitegully.gully.network import HEAD_SNAPS

#: Ways of routing flow across filled depressions and flats (``gully.flat_routing``).
FLAT_ROUTINGS = ("resolve", "epsilon", "least_cost")


@dataclass(frozen=True)
class GullyParams:
    """Method parameters (the ``gully:`` config section; defaults are the paper's).

    Attributes
    ----------
    sigma_m : float
        Gaussian σ of the smoothing (m); 10 m in the paper.
    truncate_sigmas : float
        Kernel radius and FFT zero padding in σ ([I] 4).
    depth_threshold_m : float
        Depth threshold (m); 0.25 m.
    min_patch_volume_m3 : float
        Minimum patch volume (m³); 1 m³.
    connectivity : int
        Patch connectivity, 4 or 8 ([I] 8).
    flat_routing : str
        How flow crosses filled depressions and flats ([I] ``resolve``): ``resolve`` =
        priority-flood fill without gradient (ε = 0), then flat resolution (Barnes et al.
        2014: towards lower and away from higher terrain, paths converge); ``epsilon`` =
        priority-flood+ε fill, steepest descent on it (paths cross flats on parallel lines);
        ``least_cost`` = directions by least-cost search on the unfilled tracing surface
        (:func:`kitegully.terrain.least_cost.least_cost_directions`, after GRASS
        ``r.watershed``): a depression is left through the same spill cell as the fill, but
        the route inside it follows its lowest cells (a channel under a filled reach) instead
        of the flat's shape; the ε = 0 fill is still made for the other steps.
    fill_epsilon_m : float
        Priority-flood ε (m per cell) of ``flat_routing: epsilon`` ([I] 1e-4).
    water_min_area_m2 : float or None
        Interior nodata holes of the DEM at least this large are open water (no
        photogrammetric match on water): they are not interpolated, so the traced network
        ends at their shore like at the DEM edge ([I] 2500 m² = 0.25 ha); ``None``
        interpolates every interior hole.
    head_snap : str
        Where a digitised head is moved to (:data:`kitegully.gully.network.HEAD_SNAPS`):
        ``lowest`` cell, ``deepest`` cell of the depth map, nearest cell of a kept
        depth ``patch``, lowest cell below the local slope ``plane`` (of the smoothed
        DEM), or nearest cell of a visible ``incision`` (the automatic detector's incision
        map, so it needs the ``automatic_heads`` parameters), within ``head_snap_radius_m``
        (see :func:`kitegully.gully.network.snap_heads`), or deepest cell of the head-scale
        ``relief`` below the ground surface (the same map, before its threshold).
    head_snap_radius_m : float
        Search radius of the head snapping (m), e.g. 3× the digitising SD of the heads (P(r ≤ 3σ) = 1 − e^(−4.5) ≈ 99 % for a 2-D Gaussian error).
    trace_smoothing_m : float
        Gaussian σ (m) of a smoothing of the DEM used only for the flow tracing (0 = trace
        on the DEM itself); the depth map always uses the raw DEM.
    trace_ground : bool
        Trace on the ground, not on the objects standing on it ([I] ``true`` on a
        photogrammetric DSM): cells of the tracing surface standing more than
        ``relief_k``·max(σ_z, ρ) above the ground surface (:func:`kitegully.gully.relief.ground_surface`,
        the automatic detector's; σ_z the DSM noise at the checkpoints, ρ the surface's
        head-scale micro-relief) are shrubs, trees or hedgerows and take the ground
        surface's elevation (a progressive-morphological-filter step, Zhang et al. 2003,
        with the elevation threshold from the DSM's own noise). Water runs on the soil
        under a shrub: on the DSM a 1 m shrub crown over a gully floor is a 1 m dam, and
        the steepest-descent path goes round it, down the field beside the gully, or
        spills from the depression the fill makes behind it. Needs ``gully.automatic_heads``.
        ``false`` = trace on the DSM (the DTM of a lidar or TLS survey has no objects).
        Measured worse over the six ensemble DSMs (digitised good fit 77.9 → 68.6 % mean):
        the crown hides the incision from the depth map too, so the paths under it are
        clipped from the map, and the ground surface lowers gully rims; hence off by default.
    buffer_m : float
        Buffer around the network (m); 15 m.
    crowns : CrownParams
        Shrub and tree crowns seen in the orthophoto (``gully.crowns``, optional, off by
        default; :mod:`kitegully.gully.crowns`): the tracing surface under them is the
        harmonic interpolation of the DSM around them, and traced reaches hidden by them
        between two mapped reaches count as mapped. Needs the orthophoto and
        ``gully.automatic_heads``.
    edge_inlets : bool
        Also trace from where a channel enters the DEM across its outer edge
        (:mod:`kitegully.gully.inlets`; optional, off by default): a depth patch crossing
        the edge band (2σ, ``sigma_m``) whose path from the band's end stays in the patches
        another 2σ inward, at least half of that way and of its course across the band
        incised at the head scale (needs ``gully.automatic_heads``); paths follow that course
        from two cells inside the edge. Such a channel's head lies outside the survey, so
        nobody can digitise it.
    """

    sigma_m: float = 10.0
    truncate_sigmas: float = 4.0
    depth_threshold_m: float = 0.25
    min_patch_volume_m3: float = 1.0
    connectivity: int = 8
    flat_routing: str = "resolve"
    fill_epsilon_m: float = 1e-4
    water_min_area_m2: float | None = 2500.0
    head_snap: str = "lowest"
    head_snap_radius_m: float = 1.0
    trace_smoothing_m: float = 0.0
    buffer_m: float = 15.0
    trace_ground: bool = False
    crowns: CrownParams = CrownParams()
    edge_inlets: bool = False

    @property
    def needs_ground_surface(self) -> bool:
        """``crowns`` and ``trace_ground`` stand on the incision map's ground surface and threshold
        (``gully.automatic_heads``), whatever the heads are."""
        return self.crowns.enabled or self.trace_ground

    @property
    def needs_incision_params(self) -> bool:
        """Rules that read ``gully.automatic_heads`` whatever the heads are: the ground surface's and
        ``edge_inlets`` (its channels must be incised at the head scale)."""
        return self.needs_ground_surface or self.edge_inlets

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "GullyParams":
        """Build from the ``gully:`` config section (keys of the same names; ``trace_ground``,
        ``crowns`` and ``edge_inlets`` are optional, default off)."""
        optional = {"trace_ground", "crowns", "edge_inlets"}
        kw = {k: cfg[k] for k in cls.__dataclass_fields__ if k not in optional or k in cfg}
        if "crowns" in kw:
            kw["crowns"] = CrownParams.from_config(kw["crowns"])
        return cls(**kw)

    def __post_init__(self) -> None:
        if self.flat_routing not in FLAT_ROUTINGS:
            raise ValueError(f"flat_routing must be one of {FLAT_ROUTINGS}, got {self.flat_routing!r}")
        if self.head_snap not in HEAD_SNAPS:
            raise ValueError(f"head_snap must be one of {HEAD_SNAPS}, got {self.head_snap!r}")
        if self.head_snap == "posterior" and not self.head_snap_radius_m > 0:
            raise InputError("gully.head_snap_radius_m: head_snap posterior needs a positive radius "
                             f"(3 x the heads' digitising SD), got {self.head_snap_radius_m!r}")

