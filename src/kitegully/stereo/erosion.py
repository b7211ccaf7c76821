"""Process models of the rain runs (twin side): settlement of loose soil, WEPP interrill and flow detachment.

They make the true surface of the rain series (:func:`kitegully.stereo.stage.measure_rain`); the
processing never sees them. Parameters and their reasoning: :class:`kitegully.stereo.params.StereoParams`
(``rain``).
"""

from __future__ import annotations

import numpy as np


def settlement_mm(rho_b: float, seal_depth_mm: float, seal_density: float) -> float:
    """Final settlement of loose soil compacted by rain: ``s = d·(1 − ρ_b/ρ_seal)`` (mm); 0 if ρ_b ≥ ρ_seal.

    Parameters
    ----------
    rho_b : float
        Bulk density of the loose soil (g/cm³).
    seal_depth_mm : float
        Depth the rain compacts (mm).
    seal_density : float
        Density the compacted layer reaches (g/cm³).

    Returns
    -------
    float
        Settlement s (mm).
    """
    return float(seal_depth_mm * max(0.0, 1.0 - rho_b / seal_density))


def interrill_rate_kg_m2_h(K_i: float, intensity_mm_h: float, slope_deg: float) -> float:
    """WEPP interrill detachment ``D_i = K_i·I²·S_f`` with ``S_f = 1.05 − 0.85·exp(−4·sin θ)`` (kg/m²/h).

    Parameters
    ----------
    K_i : float
        Interrill erodibility (kg·s/m⁴).
    intensity_mm_h : float
        Rain intensity I (mm/h).
    slope_deg : float
        Slope θ (degrees).

    Returns
    -------
    float
        Detachment rate D_i (kg/m²/h).
    """
    I = intensity_mm_h * 1e-3 / 3600.0
    Sf = 1.05 - 0.85 * np.exp(-4 * np.sin(np.radians(slope_deg)))
    return float(K_i * I * I * Sf * 3600.0)


def runoff_detachment_kg_m2_h(y_m: np.ndarray, intensity_mm_h: float, ksat_mm_h: float, slope_deg: float, manning_n: float,
                              K_r: float, tau_c: float) -> tuple[np.ndarray, np.ndarray]:
    """Flow shear and WEPP flow detachment of the sheet flow that accumulates down the box.

    Steady runoff per unit width ``q = (I − Ksat)·y`` (``y`` horizontal distance from the
    upslope wall), Manning depth ``h = (n q / √S)^(3/5)`` with ``S = sin θ``, shear
    ``τ = ρ g h S`` and detachment ``D_f = K_r·max(τ − τ_c, 0)`` (WEPP's rill equation without
    the transport-capacity feedback, an upper bound).

    Parameters
    ----------
    y_m : ndarray
        Distance from the upslope wall (m), ≥ 0.
    intensity_mm_h, ksat_mm_h : float
        Rain intensity and saturated conductivity (mm/h); no runoff where Ksat ≥ I.
    slope_deg : float
        Slope (deg).
    manning_n : float
        Manning roughness (s/m^(1/3)).
    K_r, tau_c : float
        Flow erodibility (s/m) and critical shear stress (Pa).

    Returns
    -------
    (ndarray, ndarray)
        Shear stress τ (Pa) and detachment D_f (kg/m²/h) at ``y_m``.
    """
    r = max(intensity_mm_h - ksat_mm_h, 0.0) * 1e-3 / 3600.0
    S = np.sin(np.radians(slope_deg))
    q = r * np.asarray(y_m, float)
    h = (manning_n * q / np.sqrt(max(S, 1e-12))) ** 0.6
    tau = 1000.0 * 9.81 * h * S
    return tau, K_r * np.maximum(tau - tau_c, 0.0) * 3600.0

