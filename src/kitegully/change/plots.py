"""Figures of the change stage: DoD map, budget bars with error bars, elevation-change histogram."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from kitegully.io.figures import map_axes, new_figure, save_figure
from kitegully.io.raster import GridSpec

if TYPE_CHECKING:
    from kitegully.change.budget import Variogram


def _decimate(a: np.ndarray, max_px: int) -> tuple[np.ndarray, int]:
    step = max(1, int(np.ceil(max(a.shape) / max_px)))
    return a[::step, ::step], step


def plot_dod_map(dod: np.ndarray, grid: GridSpec, path: str | Path, limit_m: float, max_px: int = 1500,
                 title: str = "DEM of difference (epoch 2 − epoch 1)", attribution: str | None = None) -> None:
    """DoD map, diverging colour map centred on 0 (red = lowering, blue = raising).

    Parameters
    ----------
    dod : ndarray (H, W)
        DoD (m).
    grid : GridSpec
        Grid of ``dod``; gives the map's extent.
    path : str or Path
        Output PNG file.
    limit_m : float
        Colour range ±``limit_m`` (m).
    max_px : int
        Most pixels along the longer side; the DoD is decimated by a whole step to fit.
    title : str
        Figure title.
    attribution : str or None
        Data attribution printed on the figure; None prints none.
    """
    d, _ = _decimate(dod, max_px)
    x0, y0, x1, y1 = grid.bounds
    fig, ax = new_figure(figsize=(7, 5))
    im = ax.imshow(d, cmap="RdBu", vmin=-limit_m, vmax=limit_m, extent=(x0, x1, y0, y1), interpolation="nearest")
    fig.colorbar(im, ax=ax, label="elevation change (m)", shrink=0.8, extend="both")
    map_axes(ax)
    ax.set_title(title)
    ax.grid(False)
    save_figure(fig, path, attribution)


def plot_budget_bars(budget: pd.DataFrame, path: str | Path, masks: list[str] | None = None,
                     attribution: str | None = None) -> None:
    """Net volume per mask and method with ±1σ error bars (the stated ``net_sd_m3``).

    Parameters
    ----------
    budget : DataFrame
        Budget table (:func:`kitegully.change.budget.compute_budgets`); a ``true_net_m3`` column adds the truth.
    path : str or Path
        Output PNG file.
    masks : list of str or None
        Masks to show; None shows every mask of the table.
    attribution : str or None
        Data attribution printed on the figure; None prints none.
    """
    b = budget if masks is None else budget[budget["mask"].isin(masks)]
    masks_ = list(dict.fromkeys(b["mask"]))
    methods = list(dict.fromkeys(b["method"]))
    w = 0.8 / max(len(methods), 1)
    fig, ax = new_figure(figsize=(max(6, 1.2 * len(masks_) + 2), 4))
    x = np.arange(len(masks_))
    for i, m in enumerate(methods):
        s = b[b["method"] == m].set_index("mask").reindex(masks_)
        ax.bar(x + (i - (len(methods) - 1) / 2) * w, s["net_m3"], w, label=m,
               yerr=s["net_sd_m3"], capsize=2, error_kw=dict(lw=0.8))
    if "true_net_m3" in b.columns:
        t = b[b["method"] == methods[0]].set_index("mask").reindex(masks_)["true_net_m3"]
        ax.scatter(x, t, marker="D", color="k", zorder=5, label="truth")
    ax.axhline(0, color="0.3", lw=0.8)
    ax.set_xticks(x, masks_, rotation=30, ha="right")
    ax.set_ylabel("net volume change (m³), ±1σ (correlated + co-registration)")
    ax.set_title("Sediment budget by mask and threshold")
    # outside the axes: the site's raw bar and its error bar reach the bottom corner, where a legend inside would lie
    ax.legend(fontsize=7, title="threshold", title_fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    save_figure(fig, path, attribution)


def plot_histogram(dod: np.ndarray, stable: np.ndarray, path: str | Path, limit_m: float, lod_m: float,
                   bins: int = 121, attribution: str | None = None) -> None:
    """Histogram of elevation change: all valid cells vs stable ground, LoD lines at ±LoD.

    Parameters
    ----------
    dod : ndarray (H, W)
        DoD (m); its finite cells are the valid ones.
    stable : ndarray (H, W) bool
        Stable ground.
    path : str or Path
        Output PNG file.
    limit_m : float
        Histogram range ±``limit_m`` (m); values beyond it are clipped to it.
    lod_m : float
        Level of detection (m), drawn at ±``lod_m``.
    bins : int
        Number of bins.
    attribution : str or None
        Data attribution printed on the figure; None prints none.
    """
    ok = np.isfinite(dod)
    edges = np.linspace(-limit_m, limit_m, bins + 1)
    fig, ax = new_figure(figsize=(6, 4))
    ax.hist(np.clip(dod[ok], -limit_m, limit_m), edges, color="0.5", label="all cells")
    ax.hist(np.clip(dod[ok & stable], -limit_m, limit_m), edges, histtype="step", color="tab:green", lw=1.2,
            label="stable ground")
    for v in (-lod_m, lod_m):
        ax.axvline(v, color="tab:red", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("elevation change DEM₂ − DEM₁ (m), clipped to ±%g m" % limit_m)
    ax.set_ylabel("cells")
    ax.set_title("Elevation-change histogram (dashed: ±95 % LoD at median σ)")
    ax.legend()
    save_figure(fig, path, attribution)


def plot_variogram(vg: Variogram | None, path: str | Path, attribution: str | None = None) -> None:
    """Empirical variogram of standardised stable-ground dh and its nugget + spherical fit.

    Parameters
    ----------
    vg : Variogram or None
        The fitted variogram; None draws a "not fitted" note.
    path : str or Path
        Output PNG file.
    attribution : str or None
        Data attribution printed on the figure; None prints none.
    """
    fig, ax = new_figure(figsize=(6, 4))

    if vg is None:
        ax.text(0.5, 0.5, "variogram not fitted (too few stable cells)", ha="center", transform=ax.transAxes)
        save_figure(fig, path, attribution)
        return
    e = vg.empirical
    ax.plot(e["lag_m"], e["semivariance"], "o", ms=3, label="empirical (stable ground)")
    h = np.linspace(0, float(e["lag_m"].max()), 300)
    ax.plot(h, vg.model(h), "-", label=vg.describe())
    ax.set_xlabel("lag (m)")
    ax.set_ylabel("semivariance of dh / σ_DoD (-)")
    ax.set_title("Spatial correlation of DoD errors")
    ax.legend()
    save_figure(fig, path, attribution)
