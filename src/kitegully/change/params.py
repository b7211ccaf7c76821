"""Parameters of the change stage (the ``change:`` config section, issue 17)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from kitegully import InputError
from kitegully.config import config_section

THRESHOLD_METHODS = ("min_lod", "propagated", "probabilistic", "coherence")

#: Keys of ``out`` that :func:`detect_change` writes (plus ``thresholded_<method>``).
OUTPUTS = ("dod", "sigma_dod", "stable", "coregistration", "sigma", "thresholds", "variogram", "budget",
           "headcuts", "widening", "dod_map", "budget_bars", "histogram", "variogram_png")

#: File names of :func:`detect_change`'s products in ``results/<site>/change/`` (the change rules' outputs, workflow/rules/change.smk).
OUTPUT_FILES = dict(dod="dod.tif", sigma_dod="sigma_dod.tif", stable="stable_ground.tif", coregistration="coregistration.csv",
                    sigma="sigma.csv", thresholds="thresholds.csv", variogram="variogram.csv", budget="budget.csv",
                    headcuts="headcut_retreat.csv", widening="widening.csv", dod_map="dod_map.png",
                    budget_bars="budget_bars.png", histogram="dod_histogram.png", variogram_png="variogram.png",
                    **{f"thresholded_{m}": f"dod_thresholded_{m}.tif" for m in THRESHOLD_METHODS})


@dataclass(frozen=True)
class ChangeParams:
    """Method parameters of the change stage.

    Attributes
    ----------
    coreg_enabled : bool
        Co-register epoch 2 onto epoch 1 on stable ground (Nuth & Kääb 2011 shift plus a
        plane), else take the DEMs as they are.
    coreg_max_iterations : int
        Iterations of shift + plane estimation ([I] 10; Nuth & Kääb converge in 3-5).
    coreg_tolerance_m : float
        Stop when the horizontal shift increment is below this (m) ([I] 0.01 m, a
        twentieth of a 0.2 m cell).
    coreg_tilt : bool
        Estimate and remove a plane (dz, tilt in x and y) besides the shift.
    coreg_min_slope_deg : float
        Nuth & Kääb divide dh by tan(slope): cells flatter than this carry no shift
        information and are left out of the shift fit ([I] 2°).
    coreg_max_slope_deg : float
        Steeper cells (walls, tree crowns) are left out of stable ground ([I] 60°).
    stable_max_object_height_m : float or None
        Cells standing higher than this above the epoch-1 surface's grey opening are above-ground
        objects (shrubs, trees, buildings) and not stable ground ([I] 0.15 m: grass stays below,
        shrub crowns rise above; None = keep them).
    stable_object_window_m : float
        Side of the opening window (m) ([I] 3 m, wider than a shrub crown).
    coreg_outlier_nmad : float
        Stable cells whose dh lies more than this many NMAD from the median are left out
        of each fit (vegetation growth, undetected change) ([I] 4).
    coreg_max_samples : int
        Stable cells sub-sampled per fit (deterministic stride) ([I] 500 000).
    min_lod_m : float
        (a) fixed minimum level of detection (m): |DoD| below it is set to 0. [I] Set from
        the surveys' stated accuracy, e.g. ≈ 2 × the larger epoch SD.
    t_factor : float
        (b) multiplier t of the propagated error: |DoD| > t·σ_DoD ([I] 1, GCD's
        "propagated error" default).
    confidence : float
        (c) confidence of the probabilistic threshold: |DoD|/σ_DoD > z with
        z = Φ⁻¹((1 + confidence)/2), 0.95 → 1.96.
    coherence_window : int
        (d) side of the spatial-coherence window in cells ([P] GCD: 5 × 5).
    coherence_n_low, coherence_n_high : int
        Neighbours of the same sign (of window² − 1) at which the likelihood p(E|A) of the
        spatial-coherence filter reaches its low and high values. [I] 6 and 18 for a 5 × 5
        window: symmetric about 12, the expected count for pure noise (random signs, 24/2),
        so noise alone leaves the prior unchanged on average (with 5 and 15 the false rate
        of noise at 95 % rose from 5 % to 12 % in our test).
    coherence_p_low, coherence_p_high : float
        p(E|A) at and below ``coherence_n_low`` / at and above ``coherence_n_high``
        ([I] 0.1 and 0.9: bounded away from 0 and 1 so strong evidence can win).
    variogram_max_lag_m : float
        Largest lag of the empirical variogram of stable-ground dh (m) ([I] a third of the
        site's shorter side is typical).
    variogram_bins : int
        Lag bins of the empirical variogram ([I] 30).
    variogram_samples : int
        Stable cells sampled for the variogram (all pairs, so n² / 2 pairs) ([I] 4000).
    headcut_search_radius_m : float
        Around each digitised head, the channel is searched within this radius (m): the
        digitising error plus the largest retreat expected in one season ([I] 10 m).
    headcut_incision_sigma_m : float
        Gaussian σ (m) of the smoothed surface from which the incision depth is measured
        ([I] 5 m: a few gully widths).
    headcut_min_incision_m : float
        Cells incised deeper than this (m) below the smoothed ground surface are channel
        ([I] 0.25 m, the gully stage's depth threshold). The ground surface is the grey
        opening over ``stable_object_window_m`` (shrub crowns narrower than it removed).
    headcut_window_m : float
        Horizontal resolution of the DEMs (m): the width w of the kernel that smoothed the
        head's step. [I] The dense-matching window, (2 × ``dense.matching.window_half_cells``
        + 1) × cell = 5 × 0.2 = 1.0 m on the twin; a LiDAR DEM: its cell. The channel depth is
        read from w to w + 1.5 m downstream of the coarse head (the smoothed step is at full
        depth there), the banks lie w to 2w beyond the thalweg band (outside the smoothed
        channel), a level crossing must hold over w/2, and the hillslope level is read one to
        three windows upslope of the half-height point.
    headcut_thalweg_halfwidth_m : float
        Half-width (m) of the band across the axis in which the thalweg (lowest elevation) is
        searched. [I] 0.75 m: half the widest head expected (heads 0.3-1.5 m wide), which also
        absorbs an axis error of ~15° over a 3 m retreat.
    headcut_axis_length_m : float
        The channel cells within this distance (m) of the coarse head give the downstream
        axis (their mean position). [I] 4 m: longer than the largest season's retreat (3 m)
        plus a window, short enough that a gully bends little.
    headcut_max_retreat_m : float
        The largest headcut retreat expected in one season (m) ([I] 3 m, as in
        ``search_radius_m``'s budget; field seasons on Mediterranean marls report 0.5-3 m). The
        fitted head model's lip is tried up to ``max_retreat_m + window_m`` upslope of the
        epoch-1 channel's coarse head, and its ramp may be that long; farther upslope lie
        other hollows and shrubs that a longer profile let the fit and the crossings lock on.
    headcut_profile_step_m : float
        Station spacing along the axis (m). [I] 0.1 m, half a 0.2 m cell: crossings are
        interpolated linearly between stations.
    widening_margin_m : float
        Each epoch-1 cross-section is extended by this at both ends before the edges are
        found on both DEMs ([I] 3 m: room for a season's bank retreat, about the largest
        headcut retreat, plus an end level of ground).
    widening_min_depth_m : float
        A gully edge on a section is where the depth below the line between the profile's
        end levels falls below this ([I] 0.25 m, the channel depth threshold of the
        headcuts and the gully stage).
    widening_end_m : float
        Length at each end of a profile whose median elevation is the end level ([I] 1 m,
        the dense-matching window).
    min_correlation : float or None
        A DoD cell is a measurement only where both epochs' dense matches (the epoch's
        ``correlation`` raster, NCC) reach this; others are voids, left out of the DoD, the
        stable ground and the budgets (their area is reported). [I] 0.5: for a window of
        terrain texture t plus image noise n, NCC ≈ var t / (var t + var n) = SNR²/(1 + SNR²),
        so 0.5 is SNR = 1, where the correlation peak is as much noise as terrain and a
        wrong peak (a gross error of metres) becomes likely. An epoch without a correlation
        raster has no voids; None = keep every cell.
    void_margin_m : float
        Voids (and the edges of each DEM's valid area) grow by this distance (m): a cell
        whose matching window reaches a failed match shares its image pixels, and its own
        correlation can pass while its elevation does not. [I] the dense matcher's window
        half-width (``dense.matching.window_half_cells`` × cell: 2 × 0.2 = 0.4 m on the
        twin); 0 = no margin.
    heteroscedastic : bool
        σ_DoD grows with the terrain: the propagated checkpoint σ times the ratio of the
        DoD's NMAD in the cell's (slope, curvature, height above the ground) bin on unchanged
        ground to the NMAD of the checkpoints' bins (of all unchanged cells when no epoch has
        checkpoints), at least 1 (:mod:`kitegully.change.error_model`, Hugonnet et al. 2022).
        [I] on for the photogrammetric twins: their checkpoints lie on open level ground,
        where the DoD is most precise. Tiled sites fit the same model once from the tiles
        (:mod:`kitegully.change.tiles`).
    checkpoint_outlier_nmad : float or None
        An epoch whose accuracy is given by checkpoints: checkpoints farther than this many
        NMADs from the median error are blunders, counted and left out of its σ
        (:func:`kitegully.change.uncertainty.epoch_sigma`). [I] 4, as ``coreg_outlier_nmad``:
        a normal error passes with probability 0.99994; None = the SD of all.
    seed : int
        Master seed (variogram sampling).
    """

    coreg_enabled: bool = True
    coreg_max_iterations: int = 10
    coreg_tolerance_m: float = 0.01
    coreg_tilt: bool = True
    coreg_min_slope_deg: float = 2.0
    coreg_max_slope_deg: float = 60.0
    stable_max_object_height_m: float | None = 0.15
    stable_object_window_m: float = 3.0
    coreg_outlier_nmad: float = 4.0
    coreg_max_samples: int = 500_000
    min_lod_m: float = 0.1
    t_factor: float = 1.0
    confidence: float = 0.95
    coherence_window: int = 5
    coherence_n_low: int = 6
    coherence_n_high: int = 18
    coherence_p_low: float = 0.1
    coherence_p_high: float = 0.9
    variogram_max_lag_m: float = 150.0
    variogram_bins: int = 30
    variogram_samples: int = 4000
    headcut_search_radius_m: float = 10.0
    headcut_incision_sigma_m: float = 5.0
    headcut_min_incision_m: float = 0.25
    headcut_window_m: float = 1.0
    headcut_thalweg_halfwidth_m: float = 0.75
    headcut_axis_length_m: float = 4.0
    headcut_profile_step_m: float = 0.1
    headcut_max_retreat_m: float = 3.0
    widening_margin_m: float = 3.0
    widening_min_depth_m: float = 0.25
    widening_end_m: float = 1.0
    min_correlation: float | None = 0.5
    void_margin_m: float = 0.0
    checkpoint_outlier_nmad: float | None = 4.0
    heteroscedastic: bool = False
    seed: int = 0

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], seed: int = 0) -> "ChangeParams":
        """Build from the ``change:`` section's method keys.

        ``cfg`` holds ``coregistration``, ``thresholds``, ``budget`` and ``headcuts``
        sub-sections (see ``config/schema/stages/change.schema.yaml``).
        """
        sec = config_section(cfg, "change", ("coregistration", "thresholds", "budget", "headcuts"),
                             optional=("epochs", "masks", "heads_file", "figure", "evaluation", "quality", "sections_file", "widening"))
        c = config_section(sec["coregistration"], "change.coregistration", (
            "enabled", "max_iterations", "tolerance_m", "tilt", "min_slope_deg", "max_slope_deg",
            "max_object_height_m", "object_window_m", "outlier_nmad", "max_samples"))
        t = config_section(sec["thresholds"], "change.thresholds", ("min_lod_m", "t_factor", "confidence", "coherence"))
        coh = config_section(t["coherence"], "change.thresholds.coherence", ("window_cells", "n_low", "n_high", "p_low", "p_high"))
        b = config_section(sec["budget"], "change.budget", ("variogram_max_lag_m", "variogram_bins", "variogram_samples"))
        h = config_section(sec["headcuts"], "change.headcuts", ("search_radius_m", "incision_sigma_m", "min_incision_m"),
                           optional=("window_m", "thalweg_halfwidth_m", "axis_length_m", "profile_step_m", "max_retreat_m"))
        w = config_section(sec.get("widening") or {"margin_m": cls.widening_margin_m, "min_depth_m": cls.widening_min_depth_m,
                                                    "end_m": cls.widening_end_m}, "change.widening", ("margin_m", "min_depth_m", "end_m"))
        q = config_section(sec.get("quality") or {"min_correlation": cls.min_correlation, "void_margin_m": cls.void_margin_m},
                           "change.quality", ("min_correlation", "void_margin_m"), optional=("checkpoint_outlier_nmad", "heteroscedastic"))
        return cls(
            coreg_enabled=bool(c["enabled"]), coreg_max_iterations=int(c["max_iterations"]),
            coreg_tolerance_m=float(c["tolerance_m"]), coreg_tilt=bool(c["tilt"]),
            coreg_min_slope_deg=float(c["min_slope_deg"]), coreg_max_slope_deg=float(c["max_slope_deg"]),
            coreg_outlier_nmad=float(c["outlier_nmad"]), coreg_max_samples=int(c["max_samples"]),
            stable_max_object_height_m=None if c["max_object_height_m"] is None else float(c["max_object_height_m"]),
            stable_object_window_m=float(c["object_window_m"]),
            min_lod_m=float(t["min_lod_m"]), t_factor=float(t["t_factor"]), confidence=float(t["confidence"]),
            coherence_window=int(coh["window_cells"]), coherence_n_low=int(coh["n_low"]),
            coherence_n_high=int(coh["n_high"]), coherence_p_low=float(coh["p_low"]),
            coherence_p_high=float(coh["p_high"]),
            variogram_max_lag_m=float(b["variogram_max_lag_m"]), variogram_bins=int(b["variogram_bins"]),
            variogram_samples=int(b["variogram_samples"]),
            headcut_search_radius_m=float(h["search_radius_m"]),
            headcut_incision_sigma_m=float(h["incision_sigma_m"]),
            headcut_min_incision_m=float(h["min_incision_m"]),
            headcut_window_m=float(h.get("window_m", cls.headcut_window_m)),
            headcut_thalweg_halfwidth_m=float(h.get("thalweg_halfwidth_m", cls.headcut_thalweg_halfwidth_m)),
            headcut_axis_length_m=float(h.get("axis_length_m", cls.headcut_axis_length_m)),
            headcut_profile_step_m=float(h.get("profile_step_m", cls.headcut_profile_step_m)),
            headcut_max_retreat_m=float(h.get("max_retreat_m", cls.headcut_max_retreat_m)),
            min_correlation=None if q["min_correlation"] is None else float(q["min_correlation"]),
            void_margin_m=float(q["void_margin_m"]),
            checkpoint_outlier_nmad=(None if q.get("checkpoint_outlier_nmad", cls.checkpoint_outlier_nmad) is None
                                     else float(q.get("checkpoint_outlier_nmad", cls.checkpoint_outlier_nmad))),
            heteroscedastic=bool(q.get("heteroscedastic", cls.heteroscedastic)),
            widening_margin_m=float(w["margin_m"]),
            widening_min_depth_m=float(w["min_depth_m"]), widening_end_m=float(w["end_m"]), seed=int(seed),
        )

    def __post_init__(self) -> None:
        if not 0.5 <= self.confidence < 1.0:
            raise InputError(f"change.thresholds.confidence must be in [0.5, 1), got {self.confidence}")
        if self.coherence_window < 3 or self.coherence_window % 2 == 0:
            raise InputError(f"change.thresholds.coherence.window_cells must be odd and >= 3, got {self.coherence_window}")
        if not 0 <= self.coherence_n_low < self.coherence_n_high <= self.coherence_window**2 - 1:
            raise InputError("change.thresholds.coherence: need 0 <= n_low < n_high <= window_cells² - 1")
        if self.min_correlation is not None and not -1.0 <= self.min_correlation < 1.0:
            raise InputError(f"change.quality.min_correlation must be in [-1, 1) (an NCC) or null, got {self.min_correlation}")
        if not (self.widening_margin_m > 0 and self.widening_min_depth_m > 0 and self.widening_end_m > 0):
            raise InputError("change.widening: margin_m, min_depth_m and end_m must be > 0 m")
        if not (self.headcut_window_m > 0 and self.headcut_thalweg_halfwidth_m > 0 and self.headcut_axis_length_m > 0
                and self.headcut_max_retreat_m > 0 and 0 < self.headcut_profile_step_m <= self.headcut_window_m / 2):
            raise InputError("change.headcuts: window_m, thalweg_halfwidth_m, axis_length_m and max_retreat_m must be > 0 m and "
                             "profile_step_m in (0, window_m / 2]")
        if self.checkpoint_outlier_nmad is not None and not self.checkpoint_outlier_nmad > 0:
            raise InputError(f"change.quality.checkpoint_outlier_nmad must be > 0 or null, got {self.checkpoint_outlier_nmad}")
        if self.void_margin_m < 0:
            raise InputError(f"change.quality.void_margin_m must be >= 0 m, got {self.void_margin_m}")
        if not 0.0 < self.coherence_p_low < self.coherence_p_high < 1.0:
            raise InputError("change.thresholds.coherence: need 0 < p_low < p_high < 1")
