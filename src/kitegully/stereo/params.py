"""Parameters of the ``stereo`` stage (config section ``stereo``), checked once when a rule starts."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

from kitegully import InputError
from kitegully.config import config_section
from kitegully.stereo.matching import MatchParams


def as_floats(v: Any, where: str, n: int | None = None) -> tuple[float, ...]:
    """A config list as floats, or one sentence naming the key.

    Parameters
    ----------
    v
        The config value (a list of numbers).
    where : str
        Its key, for the message (``stereo.rain.bulk_densities``).
    n : int or None
        Required length; None accepts any.

    Returns
    -------
    tuple of float

    Raises
    ------
    InputError
        When ``v`` is not a list of numbers or not ``n`` long.
    """
    try:
        out = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise InputError(f"{where}: must be a list of numbers, got {v!r}") from None
    if n is not None and len(out) != n:
        raise InputError(f"{where}: must hold {n} numbers, got {len(out)}")
    return out


def _positive(where: str, **vals: float) -> None:
    for k, v in vals.items():
        if not (v > 0):
            raise InputError(f"{where}.{k}: must be positive, got {v}")


#: Calibration image sets (``stereo.calibration.stations``).
STATIONS = ("paper", "paper+convergent", "paper+convergent+corners")


@dataclass(frozen=True)
class StereoParams:
    """Parameters of the stereo stage (config section ``stereo``; keys as below, nested).

    Attributes
    ----------
    calibration.stations : str
        ``"paper"`` = the paper's 6 parallel images shifted over the field at H ≈ 3 m;
        ``"paper+convergent"`` = those 6 plus ``n_convergent`` convergent, rolled images;
        ``"paper+convergent+corners"`` = those 14 plus ``n_corner`` convergent images turned
        so the field's centre is imaged ``corner_fraction`` of the way to a frame corner.
        [I] see :func:`kitegully.stereo.control_field.convergent_poses`: near-nadir images
        cannot separate f from the camera distance against a 0.2 mm field error, and K1 is
        only told from K2 where targets reach the frame's corners.
    calibration.n_corner, calibration.corner_fraction : int, float
        The corner images (optional; default 8 and 0.5).
    calibration.weighted_control : bool
        Adjust the field coordinates as observations with σ = ``field_sigma_mm``
        (free network with weighted control) instead of holding them fixed.
    calibration.H_m : float
        Height of the calibration images (m) [P] ≈ 3.0.
    calibration.target_sigma_px : float
        Target measurement precision (px). [I] 0.1 px: centroids of round targets ~10 px wide.
    calibration.targets : str
        ``"rendered"``: each target a printed disc rendered into the photographs and located
        (template + weighted centroid, :func:`kitegully.stereo.calibration_targets.measure_targets`), the
        bundle weighted with the median centroid σ from the noise; ``"simulated"``: projections +
        N(0, ``target_sigma_px``) (the session-9 model; the calibration test at H = 2–6 m always uses it).
    calibration.target_diameter_mm, calibration.image_noise_dn : float
        Printed disc (mm) [I] 10: 15–18 px across at 3.0–3.6 m (see ``TARGET_DIAMETER_M``); image noise (DN) [I] 1.
    calibration.field_sigma_mm : float
        Accuracy of the field coordinates (mm) [P] 0.2.
    calibration.convergent_offset_m, calibration.n_convergent : float, int
        Radius of the circle of convergent stations (m) and their number.
    calibration_test.H_m, calibration_test.B_m : list of float, float
        [P] 5 heights 2.0–6.0 m at B = 1.0 m.
    processing.image_noise_dn : float
        Image noise (DN of 255) [I] 1 DN, a well exposed 12-bit raw scaled to 8 bit.
    processing.mark_diameter_mm : float
        Diameter of the printed white disc of each frame mark (on a black plate 2.4 × as wide,
        :class:`kitegully.stereo.measure.MarkDesign`). [I] 10 mm: ≥ 10 px across at the highest
        set-up (11.6 px at H 4.7 m, 0.86 mm ground pixel), enough for a centroid of every pixel
        of the disc (close-range practice asks for ≥ 5 px). Tie points and marks are measured in
        the photographs (SIFT; template + weighted centroid); their precision is what the images give.
    processing.mark_sigma_mm : float
        Accuracy of the surveyed frame-mark coordinates (mm). [I] 0.1 mm.
    processing.manual_sigma_px : float
        Precision of manual point matching of a nail head (px). [I] 0.3 px.
    processing.reorient_each_pair : bool
        Orient every pair of a series (removals, rain epochs) on its own measurement of the
        10 frame marks (True) or reuse the first pair's absolute orientation (False). [I] True:
        each DEM of the paper is made on its own, so its orientation errors (offset and tilt,
        ∝ L like the matching's) do not cancel in a DEM of difference.
    processing.cell_mm : float
        DEM cell (mm). [I] 5 mm: ~10 × 10 matched pixels per cell at L = 9.1 m.
    processing.matching : mapping
        :class:`kitegully.stereo.matching.MatchParams` keys (window_px, search_px, min_ncc, sigma_px).
    dry_box.setups : list of [H, B]
        The 11 set-ups (m) [P] H 2.4–4.7, B 0.3–1.0 (L 5–35 m); [I] the pairs themselves.
    dry_box.removals, dry_box.removal_ml, dry_box.bulk_density : int, float, float
        [P] 16 removals; [I] 50 mL each (METHODS 4.6); [P] ρ_b 1.09 g/cm³ (Table 2).
    dry_box.removal_H_m, dry_box.removal_B_m : float
        Geometry of the removals [P] L = 9.1 m (H 2.7, B 0.8).
    rain.bulk_densities : list of float
        [P] 0.91 / 0.98 / 1.09 g/cm³.
    rain.intensity_mm_h, rain.duration_min, rain.slope_deg, rain.H_m, rain.B_m, rain.interval_min : float
        [P] 60 mm/h, 60 min, 10°, H 2.7 m, B 0.8 m; [I] a pair every 10 min.
    rain.interrill_erodibility : float
        WEPP interrill erodibility K_i (kg·s/m⁴) in ``D_i = K_i·I²·S_f``. [I] 1.0e6, the
        low end of WEPP's range for clay soils (56 % clay, Table 2); the same for all densities.
    rain.seal_depth_mm, rain.seal_density : float
        Settlement model [I]: rain compacts the top ``seal_depth_mm`` from ρ_b to
        ``seal_density`` (g/cm³), exponentially with time constant ``settle_min``, so the
        settlement per density is ``s = d·(1 − ρ_b/ρ_seal)`` (stated in rain_runs.csv).
        [I] 10 mm (raindrop compaction and slaking reach a few mm to ~1 cm) and 1.20 g/cm³
        (a sealed clay crust is denser than the densest packed box, 1.09). Not fitted to the paper.
    rain.settle_min : float
        Time constant of the settlement (min). [I] 15 min (most of the slaking happens early).
    rain.ksat_mm_h, rain.manning_n, rain.rill_erodibility_s_m, rain.critical_shear_pa : float
        Runoff-accumulation model along the slope (:func:`runoff_detachment_kg_m2_h`): sheet flow
        ``q(y) = (I − Ksat)·y`` from the upslope wall, Manning depth, shear ``τ = ρ g h sin θ``,
        WEPP flow detachment ``D_f = K_r (τ − τ_c)`` added to the uniform interrill rate.
        [P] Ksat 6.7e-5 cm/s = 2.41 mm/h (Table 2); [I] n = 0.03 (bare smoothed soil);
        [I] WEPP baseline for soils with < 30 % sand (Table 2: 22 %): K_r = 0.0069 + 0.134·exp(−20·clay)
        = 0.0069 s/m at 56 % clay, τ_c = 3.5 Pa. Not fitted to the paper's 0.49 mm.
    wind.H_m, wind.B_m, wind.duration_min : float
        [P] H 0.6 m, B 0.3 m, 45 min.
    wind.deflation_mm, wind.ripple_mm, wind.ripple_wavelength_mm, wind.sand_density : float
        [I] Mean deflation 1.0 mm over 45 min at 4.5 m/s (a few g per cm of width per
        minute for fine sand just above threshold), ripples 1 mm high, 12 mm long, migrating
        half a wavelength; sand ρ_b 1.5 g/cm³.
    wind.cell_mm : float
        DEM cell of the tray (mm). [I] 2 mm: the ground pixel is 0.11 mm at H = 0.6 m.
    wind.mark_diameter_mm : float
        Disc diameter of the tray's frame marks (mm). [I] 2 mm: 18 px at H 0.6 m (0.11 mm ground
        pixel), and the marks with their plates stay inside both frames, which span only ±0.09 m
        across the base at that height.
    """

    calibration: Mapping[str, Any]
    calibration_test: Mapping[str, Any]
    processing: Mapping[str, Any]
    dry_box: Mapping[str, Any]
    rain: Mapping[str, Any]
    wind: Mapping[str, Any]

    KEYS = {
        "calibration": ("stations", "weighted_control", "H_m", "target_sigma_px", "field_sigma_mm", "convergent_offset_m", "n_convergent"),
        "calibration_test": ("H_m", "B_m"),
        "processing": ("image_noise_dn", "mark_diameter_mm", "mark_sigma_mm", "manual_sigma_px", "reorient_each_pair",
                       "cell_mm", "matching"),
        "dry_box": ("setups", "removals", "removal_ml", "bulk_density", "removal_H_m", "removal_B_m"),
        "rain": ("bulk_densities", "intensity_mm_h", "duration_min", "interval_min", "slope_deg", "H_m", "B_m",
                 "interrill_erodibility", "seal_depth_mm", "seal_density", "settle_min", "ksat_mm_h", "manning_n",
                 "rill_erodibility_s_m", "critical_shear_pa"),
        "wind": ("H_m", "B_m", "duration_min", "deflation_mm", "ripple_mm", "ripple_wavelength_mm", "sand_density", "cell_mm",
                 "mark_diameter_mm"),
    }

    #: optional keys (default: targets simulated)
    OPTIONAL: ClassVar[dict] = {"calibration": ("targets", "target_diameter_mm", "image_noise_dn", "n_corner", "corner_fraction")}

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "StereoParams":
        """Build from the ``stereo`` section or any subset of its sub-sections (a rule passes only what it uses)."""
        config_section(cfg, "stereo", (), optional=cls.KEYS)
        out = {}
        for sec, keys in cls.KEYS.items():
            if sec not in cfg:
                out[sec] = {}
                continue
            c = dict(config_section(cfg[sec], f"stereo.{sec}", keys, cls.OPTIONAL.get(sec, ())))
            out[sec] = c
        p = cls(**out)
        p._validate()
        return p

    def _validate(self) -> None:
        c = self.calibration
        if c:
            if c["stations"] not in STATIONS:
                raise InputError(f"stereo.calibration.stations: must be one of {', '.join(STATIONS)}, got {c['stations']!r}")
            if not 0.0 <= float(c.get("corner_fraction", 0.5)) < 1.0:
                raise InputError(f"stereo.calibration.corner_fraction: must be in [0, 1), got {c['corner_fraction']!r}")
            _positive("stereo.calibration", H_m=c["H_m"], target_sigma_px=c["target_sigma_px"], field_sigma_mm=c["field_sigma_mm"])
        if self.calibration_test:
            as_floats(self.calibration_test["H_m"], "stereo.calibration_test.H_m")
        if self.processing:
            MatchParams(**self.processing["matching"])
            _positive("stereo.processing", cell_mm=self.processing["cell_mm"], mark_diameter_mm=self.processing["mark_diameter_mm"])
        if self.dry_box:
            for s in self.dry_box["setups"]:
                H, B = as_floats(s, "stereo.dry_box.setups item", 2)
                _positive("stereo.dry_box.setups", H_m=H, B_m=B)
        if self.rain:
            for rho in as_floats(self.rain["bulk_densities"], "stereo.rain.bulk_densities"):
                if not 0 < rho < self.rain["seal_density"]:
                    raise InputError(f"stereo.rain.bulk_densities: {rho} g/cm³ must lie between 0 and seal_density "
                                     f"({self.rain['seal_density']}), or the soil would swell under rain")

