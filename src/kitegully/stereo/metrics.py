"""Accuracy measures of Moritani et al. (2010): MAE, MRE (Eqs 2–3) and fits through the origin.

M is the measured (reference) value and A the photogrammetric one. The paper fits
``MAE = a·L`` (a in mm per m of L, L = H²/B) and ``A = b·M``, both through the origin.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kitegully import InputError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


def _pair(M, A, name: str) -> tuple[np.ndarray, np.ndarray]:
    M, A = np.asarray(M, float).ravel(), np.asarray(A, float).ravel()
    if M.size != A.size:
        raise InputError(f"{name}: measured and photogrammetric values differ in length ({M.size} vs {A.size})")
    if M.size == 0:
        raise InputError(f"{name}: no values given")
    if not (np.isfinite(M).all() and np.isfinite(A).all()):
        raise InputError(f"{name}: values contain NaN or infinity")
    return M, A


def mae(M: ArrayLike, A: ArrayLike) -> float:
    """Mean absolute error ``(1/N) Σ |M_i − A_i|`` (Eq. 2), in the units of M."""
    M, A = _pair(M, A, "MAE")
    return float(np.mean(np.abs(M - A)))


def mre(M: ArrayLike, A: ArrayLike) -> float:
    """Mean relative error ``(1/N) Σ |M_i − A_i| / M_i · 100`` (Eq. 3), %; every M_i must be non-zero."""
    M, A = _pair(M, A, "MRE")
    if np.any(M == 0):
        raise InputError("MRE: a measured value is zero, so its relative error is undefined")
    return float(np.mean(np.abs(M - A) / np.abs(M)) * 100.0)


def fit_through_origin(x: ArrayLike, y: ArrayLike) -> tuple[float, float]:
    """Least-squares slope of ``y = s·x`` and its R².

    Returns
    -------
    slope, r2 : float
        ``s = Σxy / Σx²``; ``R² = 1 − Σ(y − s x)² / Σ(y − ȳ)²`` (the centred definition, so
        a line through the origin is not credited with explaining the mean).
    """
    x, y = _pair(x, y, "fit through the origin")
    sxx = float(np.sum(x * x))
    if sxx == 0:
        raise InputError("fit through the origin: all x values are zero")
    s = float(np.sum(x * y) / sxx)
    sst = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(np.sum((y - s * x) ** 2)) / sst if sst > 0 else float("nan")
    return s, r2


def fit_mae_vs_L(L_m: ArrayLike, mae_mm: ArrayLike) -> tuple[float, float]:
    """Paper's ``MAE = a·L``: slope a (mm per m of L) and R²."""
    return fit_through_origin(L_m, mae_mm)


def fit_A_vs_M(M_mm: ArrayLike, A_mm: ArrayLike) -> tuple[float, float]:
    """Paper's ``A = b·M``: slope b (dimensionless) and R²."""
    return fit_through_origin(M_mm, A_mm)
