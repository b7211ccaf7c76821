"""Sweeps of the line model: flight angle versus line length and wind, Table 2 checks."""

from __future__ import annotations

import numpy as np
import pandas as pd

from kitegully.tether.line import (
    Atmosphere,
    FlightStatus,
    Kite,
    LineMaterial,
    line_length_for_height,
    positions_for_lengths,
    solve_line,
)


def flight_angle_table(
    materials: dict[str, LineMaterial],
    kite: Kite,
    winds_m_s: list[float],
    line_lengths_m: np.ndarray,
    atmosphere: Atmosphere,
    ds_m: float = 1.0,
) -> pd.DataFrame:
    """Flight angle, kite height and downwind distance for every material × wind × length.

    Parameters
    ----------
    materials : dict of str to LineMaterial
        Lines to model, keyed by the name written in the ``material`` column.
    kite : Kite
        The kite.
    winds_m_s : list of float
        Uniform horizontal wind speeds (m/s).
    line_lengths_m : ndarray
        Line lengths (m); each material's line is solved once, down to the longest.
    atmosphere : Atmosphere
        Air density and gravity.
    ds_m : float
        Segment length of the line model (m).

    Returns
    -------
    pandas.DataFrame
        Columns ``material, wind_m_s, line_length_m, flight_angle_deg, kite_height_m,
        kite_distance_m, flies, status, grounded_length_m, top_tension_n,
        tension_over_strength``. Rows where the kite does not fly with the whole line in
        the air carry NaN geometry and say why in ``status``.
    """
    lengths = np.asarray(line_lengths_m, dtype=float)
    rows = []
    for name, material in materials.items():
        sol = solve_line(material, kite, winds_m_s, float(lengths.max()), atmosphere, ds_m)
        positions = positions_for_lengths(sol, lengths)
        for w, wind in enumerate(sol.winds_m_s):
            top = float(np.hypot(*sol.tension[w, 0]))
            over = bool(material.breaking_load_n is not None and top > material.breaking_load_n)
            for length, pos in zip(lengths, positions[w]):
                rows.append(
                    dict(
                        material=name,
                        wind_m_s=float(wind),
                        line_length_m=float(length),
                        flight_angle_deg=pos.flight_angle_deg,
                        kite_height_m=pos.height_m,
                        kite_distance_m=pos.downwind_m,
                        flies=pos.status is FlightStatus.FLYING,
                        status=pos.status.value,
                        grounded_length_m=pos.grounded_length_m,
                        top_tension_n=top,
                        tension_over_strength=over,
                    )
                )
    return pd.DataFrame(rows)


def table2_comparison(
    material: LineMaterial,
    kites: dict[str, Kite],
    winds_m_s: list[float],
    line_lengths_m: list[float],
    paper_heights_m: list[float],
    atmosphere: Atmosphere,
    ds_m: float = 1.0,
) -> pd.DataFrame:
    """Model kite heights at the paper's line lengths next to Table 2's flying heights.

    ``kites`` maps a reading label (e.g. ``"bridle_tension [I-A]"``) to the kite modelled
    under that reading. Columns: ``reading, material, wind_m_s, line_length_m,
    height_paper_m, height_model_m, difference_pct, status``.

    Parameters
    ----------
    material : LineMaterial
        The line.
    kites : dict of str to Kite
        Kite modelled under each reading, keyed by the reading's label.
    winds_m_s : list of float
        Uniform horizontal wind speeds (m/s).
    line_lengths_m : list of float
        The paper's line lengths (m).
    paper_heights_m : list of float
        Table 2's flying height for each line length (m), in the same order.
    atmosphere : Atmosphere
        Air density and gravity.
    ds_m : float
        Segment length of the line model (m).

    Returns
    -------
    pandas.DataFrame
        One row per reading × wind × line length.
    """
    rows = []
    lengths = np.asarray(line_lengths_m, dtype=float)
    for reading, kite in kites.items():
        sol = solve_line(material, kite, winds_m_s, float(lengths.max()), atmosphere, ds_m)
        positions = positions_for_lengths(sol, lengths)
        for w, wind in enumerate(sol.winds_m_s):
            for length, paper_h, pos in zip(lengths, paper_heights_m, positions[w]):
                rows.append(
                    dict(
                        reading=reading,
                        material=material.name,
                        wind_m_s=float(wind),
                        line_length_m=float(length),
                        height_paper_m=float(paper_h),
                        height_model_m=pos.height_m,
                        difference_pct=100.0 * (pos.height_m - paper_h) / paper_h,
                        status=pos.status.value,
                    )
                )
    return pd.DataFrame(rows)


def line_lengths_for_heights(
    materials: dict[str, LineMaterial],
    kite: Kite,
    winds_m_s: list[float],
    heights_m: list[float],
    atmosphere: Atmosphere,
    max_length_m: float,
    ds_m: float = 1.0,
) -> pd.DataFrame:
    """Line length the model needs to put the kite at each height, per material and wind.

    NaN (with ``reachable = False``) where the height is not reached within
    ``max_length_m`` or before the line touches the ground.

    Parameters
    ----------
    materials : dict of str to LineMaterial
        Lines to model, keyed by the name written in the ``material`` column.
    kite : Kite
        The kite.
    winds_m_s : list of float
        Uniform horizontal wind speeds (m/s).
    heights_m : list of float
        Kite heights above the operator (m).
    atmosphere : Atmosphere
        Air density and gravity.
    max_length_m : float
        Longest line solved (m).
    ds_m : float
        Segment length of the line model (m).

    Returns
    -------
    pandas.DataFrame
        One row per material × wind × height with columns ``material, wind_m_s, flying_height_m,
        line_length_m, chord_angle_deg, reachable``; ``chord_angle_deg`` is ``arcsin(height / length)``.
    """
    rows = []
    for name, material in materials.items():
        sol = solve_line(material, kite, winds_m_s, max_length_m, atmosphere, ds_m)
        for w, wind in enumerate(sol.winds_m_s):
            for h in heights_m:
                length = line_length_for_height(sol, w, h)
                rows.append(
                    dict(
                        material=name,
                        wind_m_s=float(wind),
                        flying_height_m=float(h),
                        line_length_m=length,
                        chord_angle_deg=float(np.degrees(np.arcsin(h / length))) if np.isfinite(length) and length > 0 else np.nan,
                        reachable=bool(np.isfinite(length)),
                    )
                )
    return pd.DataFrame(rows)
