"""Figures of the tether stage (Feurer et al. 2018 Figs 5–7)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.patches import Rectangle

from kitegully.io.figures import new_figure, save_figure
from kitegully.tether.line import FlightStatus, LineSolution


def _wind_colours(winds):
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    return {w: cmap(i / max(len(winds) - 1, 1)) for i, w in enumerate(winds)}


def plot_line_shapes(
    solutions: dict[str, LineSolution],
    reference: LineSolution,
    line_length_m: float,
    path: str,
) -> None:
    """Fig. 5: shapes of ``line_length_m`` of line for each wind, one panel per material.

    The perfect (weightless, dragless) line is drawn thin grey for reference. Lines that
    touch the ground, and kites that cannot fly, are named in the legend instead of drawn.

    Parameters
    ----------
    solutions : dict of str to LineSolution
        Solved line per material; the keys title the panels.
    reference : LineSolution
        The perfect line; each wind is drawn against the reference wind nearest to it.
    line_length_m : float
        Length of line drawn (m).
    path : str
        Figure file.
    """
    fig, axes = new_figure(1, len(solutions), figsize=(3.4 * len(solutions), 3.4), sharey=True, squeeze=False)
    winds = list(reference.winds_m_s)
    colours = _wind_colours(winds)
    for ax, (name, sol) in zip(axes[0], solutions.items()):
        for w, wind in enumerate(sol.winds_m_s):
            ref_w = int(np.argmin(np.abs(reference.winds_m_s - wind)))
            try:
                rx, rz = reference.shape(ref_w, line_length_m)
                ax.plot(rx, rz, color="0.6", lw=0.7, zorder=1)
            except ValueError:
                pass
            pos = sol.position(w, line_length_m)
            if pos.status is FlightStatus.FLYING:
                x, z = sol.shape(w, line_length_m)
                ax.plot(x, z, color=colours[wind], lw=1.8, label=f"{wind:g} m/s ({pos.flight_angle_deg:.1f}°)")
            else:
                ax.plot([], [], color=colours[wind], lw=1.8, ls=":", label=f"{wind:g} m/s: {pos.status.value.replace('_', ' ')}")
        ax.plot([], [], color="0.6", lw=0.7, label="perfect line")
        ax.set_title(f"{name}, {line_length_m:g} m of line")
        ax.set_xlabel("downwind distance from operator (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(loc="upper left", title="wind (flight angle)")
    axes[0, 0].set_ylabel("height above operator (m)")
    save_figure(fig, path)


def plot_flight_angle_vs_length(table: pd.DataFrame, path: str, reference_material: str | None = None) -> None:
    """Fig. 6: flight angle against line length for each wind, one panel per material.

    Parameters
    ----------
    table : DataFrame
        :func:`kitegully.tether.analysis.flight_angle_table`: columns ``material, wind_m_s, line_length_m,
        flight_angle_deg, status``.
    path : str
        Figure file.
    reference_material : str or None
        Material drawn as a dashed "perfect line" (its middle wind) in every panel instead of in its own panel.
    """
    materials = [m for m in table["material"].unique() if m != reference_material]
    fig, axes = new_figure(1, len(materials), figsize=(3.4 * len(materials), 3.2), sharey=True, squeeze=False)
    winds = sorted(table["wind_m_s"].unique())
    colours = _wind_colours(winds)
    for ax, material in zip(axes[0], materials):
        sub = table[(table["material"] == material) & (table["line_length_m"] > 0)]
        for wind in winds:
            s = sub[sub["wind_m_s"] == wind]
            ax.plot(s["line_length_m"], s["flight_angle_deg"], color=colours[wind], lw=1.5, label=f"{wind:g} m/s")
            grounded = s[s["status"] == FlightStatus.LINE_ON_GROUND.value]
            if not grounded.empty:
                ax.axvline(grounded["line_length_m"].min(), color=colours[wind], ls=":", lw=0.8)
        if reference_material is not None:
            ref = table[(table["material"] == reference_material) & (table["line_length_m"] > 0)]
            ref = ref[ref["wind_m_s"] == winds[len(winds) // 2]]
            ax.plot(ref["line_length_m"], ref["flight_angle_deg"], color="0.5", lw=0.8, ls="--", label="perfect line")
        ax.set_title(material)
        ax.set_xlabel("line length (m)")
    axes[0, 0].set_ylabel("effective flight angle (°)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=len(labels), title="wind speed")
    save_figure(fig, path)


def plot_observed_flight_angles(
    summary: pd.DataFrame,
    simulated: pd.DataFrame | None,
    path: str,
) -> None:
    """Fig. 7: min/max boxes of observed flight angles per flight.

    Each box spans the flight's line lengths (x) and the range of its measured angles (y);
    the median per line length is marked. ``simulated`` (columns ``line_length_m,
    flight_angle_deg, wind_m_s``) overlays the model's curves for the same line material.

    Parameters
    ----------
    summary : DataFrame
        :func:`kitegully.tether.gps.summarise_flight_angles`: columns ``flight, kite, line_length_m,
        min_deg, median_deg, max_deg``.
    simulated : DataFrame or None
        The model's curves; ``None`` or empty draws none.
    path : str
        Figure file.
    """
    fig, ax = new_figure(figsize=(5.5, 3.6))
    kites = list(summary["kite"].unique())
    palette = ["tab:blue", "black", "tab:orange", "tab:green"]
    kite_colour = {k: palette[i % len(palette)] for i, k in enumerate(kites)}
    for flight, s in summary.groupby("flight", sort=False):
        kite = s["kite"].iloc[0]
        lo, hi = s["line_length_m"].min(), s["line_length_m"].max()
        pad = 10.0
        rect = Rectangle(
            (lo - pad, s["min_deg"].min()),
            hi - lo + 2 * pad,
            s["max_deg"].max() - s["min_deg"].min(),
            fill=False,
            edgecolor=kite_colour[kite],
            lw=1.3,
        )
        ax.add_patch(rect)
        ax.plot(s["line_length_m"], s["median_deg"], "o", ms=3, color=kite_colour[kite])
        ax.annotate(str(flight), (hi + pad, s["max_deg"].max()), fontsize=7, color=kite_colour[kite])
    if simulated is not None and not simulated.empty:
        for wind, s in simulated.groupby("wind_m_s"):
            s = s[s["line_length_m"] > 0]
            ax.plot(s["line_length_m"], s["flight_angle_deg"], color="0.55", lw=0.8, ls="--")
        ax.plot([], [], color="0.55", lw=0.8, ls="--", label="line model (flight winds)")
    for k in kites:
        ax.plot([], [], color=kite_colour[k], lw=1.3, label=f"kite {k} (min/max box, median)")
    ax.set_xlabel("line length (m)")
    ax.set_ylabel("effective flight angle (°)")
    ax.autoscale_view()
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    save_figure(fig, path)
