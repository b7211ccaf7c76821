"""The network scoring protocol of the gully stage (paper 000 sect. 2.6.2, Fig. 9b; METHODS.md 1.6).

:func:`score_network` is the one place the protocol is assembled: DEM footprint near the
lines → scored part of the reference (heads on the DEM, inside the catchment) → Thommeret
lengths at the tolerance of the site and at its extra tolerances, against the scored
reference (paper protocol) and against the whole reference (unfiltered). The
``gully_validate`` rule, the tests and ``benchmarks/gully_benchmark.py`` all call it.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import geopandas as gpd
import numpy as np
import pandas as pd
from shapely.geometry.base import BaseGeometry

from kitegully import InputError
from kitegully.config import config_section
from kitegully.evaluate.network import (
    NetworkScorer,
    area_scores,
    footprint,
    rasterize_polygons,
    scored_reference,
    validation_geometries,
)
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)

#: Names of the two reference sets in ``network_validation_tolerances.csv``.
SCORED = "scored (paper protocol)"
UNFILTERED = "all (unfiltered)"


@dataclass(frozen=True)
class ValidationParams:
    """Settings of the network validation (the ``gully.validation`` config section).

    Attributes
    ----------
    tolerance_m : float
        Matching tolerance τ (m) of the Thommeret comparison: a network's domain is its
        buffer of τ ([I] 5 m, a few cells of the mapping DEM plus the field mapping error).
    extra_tolerances_m : tuple of float
        Further tolerances (m) reported in the tolerance table beside ``tolerance_m``.
    reference_join_m : float
        A reference line whose downstream end lies this close to another line flows into
        it ([I] a few m, the field mapping error).
    """

    tolerance_m: float = 5.0
    extra_tolerances_m: tuple[float, ...] = ()
    reference_join_m: float = 3.0

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "ValidationParams":
        """Build from the ``gully.validation`` section (``catchment_file`` is an input, not read here).

        Raises :class:`kitegully.InputError` naming the first missing or unknown key.
        """
        config_section(cfg, "gully.validation", ("tolerance_m", "extra_tolerances_m", "reference_join_m"),
                       optional=("catchment_file",))
        return cls(
            tolerance_m=float(cfg["tolerance_m"]),
            extra_tolerances_m=tuple(float(t) for t in cfg["extra_tolerances_m"]),
            reference_join_m=float(cfg["reference_join_m"]),
        )

    def __post_init__(self) -> None:
        for t in (self.tolerance_m, *self.extra_tolerances_m):
            if t < 0:
                raise ValueError(f"gully.validation: tolerances must be >= 0, got {t}")
        if self.reference_join_m < 0:
            raise ValueError(f"gully.validation.reference_join_m must be >= 0, got {self.reference_join_m}")

    @property
    def tolerances_m(self) -> list[float]:
        """Every tolerance of the tolerance table, ascending, without repeats."""
        return sorted({self.tolerance_m, *self.extra_tolerances_m})


@dataclass
class NetworkValidation:
    """Products of :func:`score_network`.

    Attributes
    ----------
    table : DataFrame
        ``category, length_m, percent`` at ``tolerance_m`` against the scored reference
        (``network_validation.csv``).
    tolerances : DataFrame
        ``tolerance_m, reference_lines, category, length_m, percent`` for every tolerance
        and both reference sets (``network_validation_tolerances.csv``).
    scored, not_scored : geometry
        Scored part of the reference and the rest (:func:`scored_reference`).
    counts : dict
        ``heads``, ``heads_on_dem``, ``pieces``, ``pieces_scored``.
    domain : geometry
        DEM footprint near the lines, where both networks are compared.
    extracted : GeoDataFrame
        The extracted network as scored (clipped to the catchment when there is one).
    pieces : dict
        Good fit, false negative, false positive and not-scored lines at ``tolerance_m``
        (:func:`validation_geometries`), for the Fig. 9b map.
    """

    table: pd.DataFrame
    tolerances: pd.DataFrame
    scored: BaseGeometry
    not_scored: BaseGeometry
    counts: dict[str, int]
    domain: BaseGeometry
    extracted: gpd.GeoDataFrame
    pieces: dict[str, BaseGeometry] = field(default_factory=dict)

    def percent(self) -> dict[str, float]:
        """Percentages of :attr:`table` by category."""
        return dict(zip(self.table["category"], self.table["percent"]))


def check_reference(reference: gpd.GeoDataFrame, path: str) -> gpd.GeoDataFrame:
    """The reference network, or :class:`InputError` when ``path`` holds no lines."""
    if not reference.geom_type.isin(["LineString", "MultiLineString"]).all() or len(reference) == 0:
        raise InputError(f"{path}: the reference network must hold lines")
    return reference


def catchment_outline(catchment: gpd.GeoDataFrame, path: str) -> BaseGeometry:
    """Union of the catchment polygons, or :class:`InputError` when ``path`` holds none."""
    if len(catchment) == 0 or not catchment.geom_type.isin(["Polygon", "MultiPolygon"]).all():
        raise InputError(f"{path}: the catchment must hold polygons")
    return catchment.geometry.union_all()


def tolerance_table(
    scorers: Mapping[str, NetworkScorer], extracted: gpd.GeoDataFrame, tolerances_m: list[float], clipped: BaseGeometry
) -> pd.DataFrame:
    """Thommeret lengths of ``extracted`` for every tolerance and every named scorer.

    The extracted buffer is made once per tolerance and shared by the scorers.

    Parameters
    ----------
    scorers : mapping of str to NetworkScorer
        Name of the reference lines → their scorer.
    extracted : lines
        The extracted network.
    tolerances_m : list of float
        Matching tolerances τ (m).
    clipped : geometry
        ``extracted`` clipped to the domain (:meth:`NetworkScorer.clip`).

    Returns
    -------
    DataFrame
        Columns ``tolerance_m, reference_lines, category, length_m, percent``; four rows per
        tolerance and scorer.
    """
    rows = []
    for t in tolerances_m:
        ebuf = NetworkScorer.buffer(clipped, t)
        for name, scorer in scorers.items():
            v = scorer.score(extracted, t, clipped, ebuf)
            v.insert(0, "reference_lines", name)
            v.insert(0, "tolerance_m", t)
            rows.append(v)
    return pd.concat(rows, ignore_index=True)


def _log_scores(table: pd.DataFrame, tolerances: pd.DataFrame, tolerance_m: float, prefix: str = "") -> None:
    pivot = tolerances.pivot_table(index=["tolerance_m", "reference_lines"], columns="category", values="percent")
    for _, r in pivot.iterrows():
        log.info("%stolerance %.3g m, reference %s: good fit %.1f %%, false positive %.1f %%, false negative %.1f %%",
                 prefix, r.name[0], r.name[1], r["good_fit"], r["false_positive"], r["false_negative"])
    pct = dict(zip(table["category"], table["percent"]))
    log.info(
        "%snetwork validation (tolerance %.3g m, paper protocol): reference %.0f m, good fit %.1f %%, "
        "false positive %.1f %%, false negative %.1f %%",
        prefix, tolerance_m, table["length_m"].iloc[0], pct["good_fit"], pct["false_positive"], pct["false_negative"],
    )


def score_network(
    reference: gpd.GeoDataFrame,
    extracted: gpd.GeoDataFrame,
    valid: np.ndarray,
    grid: GridSpec,
    params: ValidationParams,
    catchment: BaseGeometry | None = None,
    geometries: bool = True,
    label: str | None = None,
) -> NetworkValidation:
    """Score an extracted gully network against the reference network (paper protocol).

    Parameters
    ----------
    reference : GeoDataFrame
        Reference (field) network, lines in the site CRS (m), head first.
    extracted : GeoDataFrame
        The mapped network (``gully_network_mapped.gpkg``).
    valid : ndarray of bool (H, W)
        Valid cells of the mapping DEM (e.g. ``gully_map != 255``).
    grid : GridSpec
        Their grid.
    params : ValidationParams
        Tolerances and reference join distance.
    catchment : Polygon, optional
        Catchment outline: the scored reference and the extracted network are clipped to it.
    geometries : bool
        Also make the map pieces (:attr:`NetworkValidation.pieces`).
    label : str, optional
        Names the extracted network in the log lines (two networks scored side by side in
        threads, as the gully_validate rule does for ``gully.heads: both``).

    Returns
    -------
    NetworkValidation

    Notes
    -----
    Only the valid cells within 2 cells of either network are polygonised: clipping the
    lines to that polygon equals clipping them to the whole footprint, far cheaper on a
    large DEM. Complexity O(n) for n cells plus GEOS overlays O((m + k) log(m + k)) per
    tolerance for m, k line vertices.
    """
    domain = footprint(valid, grid, near=[*reference.geometry, *extracted.geometry])
    scored, not_scored, counts = scored_reference(reference, domain, params.reference_join_m, catchment)
    prefix = f"{label}: " if label else ""
    log.info(
        "%sreference: %.0f m scored, %.0f m not scored (outside the catchment or fed only by heads off the DEM); "
        "%d of %d reference heads on the DEM",
        prefix, scored.length, not_scored.length, counts["heads_on_dem"], counts["heads"],
    )
    if scored.is_empty:
        log.warning("no reference line is scored: every reference head lies off the DEM or outside the catchment")
    if catchment is not None:
        extracted = extracted.clip(catchment)
    scorers = {SCORED: NetworkScorer([scored], domain, reference_all=reference), UNFILTERED: NetworkScorer(reference, domain)}
    clipped = scorers[UNFILTERED].clip(extracted)
    table = scorers[SCORED].score(extracted, params.tolerance_m, clipped)
    tolerances = tolerance_table(scorers, extracted, params.tolerances_m, clipped)
    _log_scores(table, tolerances, params.tolerance_m, prefix)
    pieces = (
        validation_geometries([scored], extracted, params.tolerance_m, domain, reference_all=reference) if geometries else {}
    )
    return NetworkValidation(table, tolerances, scored, not_scored, counts, domain, extracted, pieces)


def score_networks(
    reference: gpd.GeoDataFrame,
    mapped: gpd.GeoDataFrame,
    digitised: gpd.GeoDataFrame | None,
    valid: np.ndarray,
    grid: GridSpec,
    params: ValidationParams,
    catchment: BaseGeometry | None = None,
) -> tuple[NetworkValidation, NetworkValidation | None]:
    """Score the mapped network and, when given, the digitised heads' network alone, side by side.

    With ``gully.heads: both`` the gully_validate rule scores the combined network (with the map
    pieces) and, for Table 4's paper procedure, the network of the digitised heads alone (without
    them). The second runs in a thread beside the first: the scoring is mostly GEOS buffers and
    overlays, which release the GIL (full size: 136 s one after the other, 73–99 s side by side).

    Parameters
    ----------
    reference : GeoDataFrame
        Reference (field) network, lines in the site CRS (m), head first.
    mapped : GeoDataFrame
        The mapped network (``gully_network_mapped.gpkg``).
    digitised : GeoDataFrame or None
        The digitised heads' mapped network alone (``gully_network_mapped_digitised.gpkg``); None: not scored.
    valid : ndarray of bool (H, W)
        Valid cells of the mapping DEM.
    grid : GridSpec
        Their grid.
    params : ValidationParams
        Tolerances and reference join distance.
    catchment : Polygon, optional
        Catchment outline (:func:`score_network`).

    Returns
    -------
    mapped, digitised : NetworkValidation, NetworkValidation or None
        :func:`score_network` of each; the second has no map pieces, and is None without ``digitised``.
    """
    if digitised is None:
        return score_network(reference, mapped, valid, grid, params, catchment), None
    with ThreadPoolExecutor(max_workers=1) as pool:
        alone = pool.submit(score_network, reference, digitised, valid, grid, params, catchment, geometries=False,
                            label="digitised heads alone")
        res = score_network(reference, mapped, valid, grid, params, catchment, label="all heads")
        return res, alone.result()


def score_gully_areas(truth_polygons: gpd.GeoDataFrame, maps: Mapping[str, tuple[np.ndarray, GridSpec]]) -> pd.DataFrame:
    """Cell-wise precision, recall and IoU of gully maps against the truth polygons (twins, evaluation).

    Parameters
    ----------
    truth_polygons : GeoDataFrame
        The twin's true gully polygons.
    maps : mapping
        Map variant name → (gully map, grid); the map holds 1 gully, 0 not, 255 off the DEM
        (cells off the DEM are left out of the truth too).

    Returns
    -------
    DataFrame
        ``map_variant`` and the :func:`kitegully.evaluate.network.area_scores` columns, one row per map.
    """
    rows = []
    for name, (gully, grid) in maps.items():
        truth = rasterize_polygons(truth_polygons, grid) & (gully != 255)
        s = area_scores(gully == 1, truth, grid.cell)
        rows.append({"map_variant": name, **s})
        log.info("area scores (%s): %s", name, s)
    return pd.DataFrame(rows)
