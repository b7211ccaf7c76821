"""Vertical datum check of the DSM at the ground control targets (issue 17, epoch 2).

Why: the GCP bundle adjustment sets the block's height from the GCP *clicks* alone. A
target seen in 4-5 near-nadir photos (base/height 0.2-0.3) and clicked with 0.7 px noise
is intersected to only 0.10-0.19 m in height, so nine such targets fix the block's
vertical datum to about 0.05 m (1 SD), and one click draw can leave the whole block
0.1 m high while every GCP passes its own leave-one-out test (each misfit is within
its large expected SD). The dense DSM measures the same targets far better: every cell
is matched by NCC over all the photos that see it (6-9 here) with the target's own
black/white pattern in the window, so the DSM's height on a target has the checkpoint
NMAD of a few cm, not the click intersection's decimetre. The DSM at the surveyed
targets is therefore an independent and sharper check of the datum, the check a
photogrammetrist makes on the DEM before delivering it (the DEM's residuals at the
control points).

:func:`check_datum` samples the DSM on every surveyed target used by the adjustment
(median of the valid cells within ``window_m`` of its centre, i.e. on the flat target),
drops targets whose difference lies more than ``outlier_nmad`` robust SDs from the
median (a target knocked over and not re-surveyed, a matching failure), and tests the
mean difference against zero with Student's t at ``confidence``. A significant mean is
a datum error of the block: it is subtracted from the whole DSM (a vertical shift, the
only term nine targets determine well; tilt is left to the change stage's
co-registration). A non-significant mean is left alone, so a block whose datum the
clicks got right is not moved by the DSM's own noise.

Cost: O(targets × window cells) after the matching.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import pandas as pd
from scipy import stats

from kitegully import InputError
from kitegully.config import checked_number, config_section
from kitegully.evaluate.dem import nmad
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)

DATUM_COLUMNS = ["gcp_id", "x_m", "y_m", "z_survey_m", "z_dsm_m", "n_cells", "dz_m", "used", "note"]


@dataclass(frozen=True)
class DatumParams:
    """The ``dense.datum`` section: vertical datum check at the GCP targets.

    Attributes
    ----------
    enabled : bool
        Run the check (and shift the DSM when the offset is significant).
    window_m : float
        Radius (m) around a target's surveyed centre whose valid DSM cells give its
        height ([I] half the target's side, 0.5 m for 1 m targets: the cells lie on
        the flat target, whose own pattern the matching window sees).
    confidence : float
        Two-sided confidence of the t-test on the mean DSM − survey difference
        ([I] 0.95: a shift is applied only when the datum error is clear of the noise).
    min_gcps : int
        Fewest targets with a DSM height for the test ([I] 4: a mean and an SD with
        three degrees of freedom).
    outlier_nmad : float
        Targets more than this many robust SDs (1.4826 × MAD, at least ``min_sd_m``)
        from the median difference are left out ([I] 3).
    min_sd_m : float
        Floor of the robust SD in the outlier test (m; [I] the DSM's noise on open
        ground, 0.05 m at the default twin's checkpoints, so that targets agreeing to a
        few mm do not make a 1 cm difference look like an outlier).
    """

    enabled: bool
    window_m: float
    confidence: float
    min_gcps: int
    outlier_nmad: float
    min_sd_m: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None) -> "DatumParams":
        """Build from ``dense.datum``; None = disabled. Raises InputError naming a bad key."""
        if cfg is None:
            return cls(False, 0.5, 0.95, 4, 3.0, 0.05)
        config_section(cfg, "dense.datum", cls.__dataclass_fields__)
        p = cls(enabled=bool(cfg["enabled"]), window_m=float(cfg["window_m"]), confidence=float(cfg["confidence"]),
                min_gcps=int(cfg["min_gcps"]), outlier_nmad=float(cfg["outlier_nmad"]), min_sd_m=float(cfg["min_sd_m"]))
        checked_number(cfg, "window_m", "dense.datum")
        checked_number(cfg, "min_gcps", "dense.datum", 3, strict=False)
        if not 0.5 <= p.confidence < 1:
            raise InputError(f"dense.datum.confidence: must lie in [0.5, 1), got {cfg['confidence']!r}")
        if p.outlier_nmad <= 0 or p.min_sd_m < 0:
            raise InputError("dense.datum: outlier_nmad must be positive and min_sd_m at least 0")
        return p


@dataclass
class DatumCheck:
    """Result of :func:`check_datum`.

    Attributes
    ----------
    offset_m : float
        Mean DSM − survey height over the kept targets (NaN when too few).
    se_m : float
        Its standard error, SD / √n (m).
    n : int
        Targets kept.
    t_crit : float
        Student's t at the confidence for n − 1 degrees of freedom.
    applied : bool
        Whether the DSM was shifted by −offset.
    reason : str
        One sentence saying what was decided and why.
    table : DataFrame
        One row per target, columns :data:`DATUM_COLUMNS`.
    """

    offset_m: float
    se_m: float
    n: int
    t_crit: float
    applied: bool
    reason: str
    table: pd.DataFrame

    def summary(self) -> dict[str, float]:
        """Rows for the dense summary table."""
        return {"datum_offset_m": self.offset_m, "datum_offset_se_m": self.se_m, "datum_gcps": float(self.n),
                "datum_shift_applied_m": -self.offset_m if self.applied else 0.0}


def dsm_height_at(dsm: np.ndarray, grid: GridSpec, x: float, y: float, radius_m: float) -> tuple[float, int]:
    """Median of the valid DSM cells whose centres lie within ``radius_m`` of (x, y), and their count.

    Parameters
    ----------
    dsm : ndarray (rows, cols)
        The DSM (m, NaN = no value) on ``grid``.
    grid : GridSpec
        Its grid.
    x, y : float
        The point (site CRS, m).
    radius_m : float
        Radius of the disc whose cells are used (m).

    Returns
    -------
    z : float
        Median height of the valid cells in the disc (m); NaN when there are none.
    n : int
        Number of valid cells in the disc.
    """
    r, c = grid.rowcol(np.array([x]), np.array([y]))
    k = int(np.ceil(radius_m / grid.cell)) + 1
    r0, c0 = int(np.floor(r[0])), int(np.floor(c[0]))
    rows = np.arange(max(r0 - k, 0), min(r0 + k + 2, grid.height))
    cols = np.arange(max(c0 - k, 0), min(c0 + k + 2, grid.width))
    if len(rows) == 0 or len(cols) == 0:
        return float("nan"), 0
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    # cell centres: fractional row/col of a point is measured from cell centres (GridSpec.rowcol)
    inside = (rr - r[0]) ** 2 + (cc - c[0]) ** 2 <= (radius_m / grid.cell) ** 2
    v = dsm[rr[inside], cc[inside]]
    v = v[np.isfinite(v)]
    return (float(np.median(v)), int(len(v))) if len(v) else (float("nan"), 0)


def check_datum(dsm: np.ndarray, grid: GridSpec, gcps: pd.DataFrame, params: DatumParams) -> DatumCheck:
    """Test the DSM's vertical datum at the surveyed targets (module docstring).

    Parameters
    ----------
    dsm : ndarray (rows, cols)
        The DSM (m, NaN = no value) on ``grid``.
    grid : GridSpec
        Its grid.
    gcps : DataFrame
        Columns ``gcp_id, x, y, z`` (site CRS, m) of the targets the adjustment used.
    params : DatumParams
        The check's settings.

    Returns
    -------
    DatumCheck
        Offset, its SE, the decision and the per-target table. The DSM is not changed
        here; the caller subtracts ``offset_m`` when ``applied``.
    """
    rows = []
    for g in gcps.itertuples(index=False):
        z, n = dsm_height_at(dsm, grid, float(g.x), float(g.y), params.window_m)
        rows.append({"gcp_id": str(g.gcp_id), "x_m": float(g.x), "y_m": float(g.y), "z_survey_m": float(g.z),
                     "z_dsm_m": z, "n_cells": n, "dz_m": z - float(g.z), "used": bool(np.isfinite(z)),
                     "note": "" if np.isfinite(z) else "no_dsm_value"})
    table = pd.DataFrame(rows, columns=DATUM_COLUMNS)
    dz = table["dz_m"].to_numpy(float)
    ok = np.isfinite(dz)
    if ok.sum() >= 3:
        med = np.median(dz[ok])
        sd_rob = max(nmad(dz[ok]), params.min_sd_m)
        far = ok & (np.abs(dz - med) > params.outlier_nmad * sd_rob)
        table.loc[far, "used"] = False
        table.loc[far, "note"] = f"outlier (> {params.outlier_nmad:g} robust SD from the median)"
        ok &= ~far
    n = int(ok.sum())
    if n < params.min_gcps:
        reason = f"datum check skipped: {n} targets with a DSM height, at least {params.min_gcps} needed"
        return DatumCheck(float("nan"), float("nan"), n, float("nan"), False, reason, table)
    mean = float(np.mean(dz[ok]))
    se = float(np.std(dz[ok], ddof=1) / np.sqrt(n))
    t_crit = float(stats.t.ppf(0.5 + params.confidence / 2, n - 1))
    applied = bool(abs(mean) > t_crit * se)
    verdict = "significant: the DSM is shifted by" if applied else "not significant: the DSM is left as matched (shift would be"
    reason = (f"DSM - survey at {n} targets: mean {mean:+.3f} m, SE {se:.3f} m, |t| = {abs(mean) / max(se, 1e-12):.1f} "
              f"against {t_crit:.2f} at {params.confidence:.0%}; {verdict} {-mean:+.3f} m" + ("" if applied else ")"))
    return DatumCheck(mean, se, n, t_crit, applied, reason, table)


def used_gcps(gcp_file: str, residuals_csv: str, crs: str, gcp_format: str = "auto", csv_crs: str | None = None) -> pd.DataFrame:
    """``gcp_id, x, y, z`` of the GCPs in ``gcp_file`` that the adjustment used (``used`` in its residual table).

    Targets the georeferencing QA left out (outlier, ray miss, a moved target with a
    stale coordinate) are not used to judge the DSM either.

    Parameters
    ----------
    gcp_file : str
        The GCP file (ODM list or CSV).
    residuals_csv : str
        The georef stage's ``gcp_residuals.csv``; needs the columns ``gcp_id`` and ``used``.
    crs : str
        The site CRS the coordinates are returned in.
    gcp_format : str
        Format of ``gcp_file``: ``odm``, ``csv`` or ``auto`` (by suffix).
    csv_crs : str or None
        CRS of the coordinates in a CSV file; None = the site CRS.

    Returns
    -------
    DataFrame
        Columns ``gcp_id, x, y, z`` (site CRS, m), one row per used target.

    Raises
    ------
    InputError
        When ``residuals_csv`` lacks the columns ``gcp_id`` or ``used``.
    """
    from kitegully.georef.gcp_io import read_gcps

    res = pd.read_csv(residuals_csv)
    if not {"gcp_id", "used"} <= set(res.columns):
        raise InputError(f"{residuals_csv}: needs the columns gcp_id and used (the georef stage's gcp_residuals.csv)")
    used = set(res.loc[res["used"].astype(str).str.lower() == "true", "gcp_id"].astype(str))
    rows = [{"gcp_id": g.gcp_id, "x": g.xyz[0], "y": g.xyz[1], "z": g.xyz[2]} for g in read_gcps(gcp_file, crs, gcp_format, csv_crs)
            if g.gcp_id in used]
    return pd.DataFrame(rows, columns=["gcp_id", "x", "y", "z"])
