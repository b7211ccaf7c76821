"""Validation of an extracted gully network and gully map (paper 000 sect. 2.6.2).

Line lengths follow Thommeret et al. (2010), with every percentage relative to the
reference length ``L_ref``:

* good fit: reference length inside the extracted-network domain;
* false negative: reference length outside it (good fit + FN = L_ref);
* false positive: extracted length outside the reference domain.

[I] The "domain" of a network is a buffer of τ around it (default 5 m). Area scores
compare a gully map with truth polygons cell by cell.

The paper scores only reference gullies inside the catchment whose heads fall within the
DEM (Fig. 9b, green lines): :func:`scored_reference` splits the reference into the part
that is scored and the part that is not. Reference lines left out of the score still
are gullies on the ground, so extracted lines along them are no false positives.
"""

from __future__ import annotations

from collections.abc import Iterable

import cv2
import geopandas as gpd
import numpy as np
import pandas as pd
import rasterio.features
import shapely
import shapely.geometry
from shapely.geometry.base import BaseGeometry
from shapely.ops import substring

from kitegully.io.raster import GridSpec

CATEGORIES = ("reference", "good_fit", "false_positive", "false_negative")


def _lines(geoms: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry]) -> BaseGeometry:
    if isinstance(geoms, gpd.GeoDataFrame):
        geoms = geoms.geometry
    arr = [g for g in geoms if g is not None and not g.is_empty]
    return shapely.union_all(arr) if arr else shapely.GeometryCollection()


def _buffer(lines: BaseGeometry, distance: float) -> BaseGeometry:
    """Buffer of a line network: each line buffered on its own, then one cascaded union.

    Same set as ``lines.buffer(distance)`` up to GEOS's polygonal approximation of the
    round joins (areas differ by slivers of < 0.01 m² at metre tolerances), and several
    times faster on long traced networks with many vertices.
    """
    parts = shapely.get_parts(lines)
    if parts.size == 0:
        return shapely.GeometryCollection()
    return shapely.union_all(shapely.buffer(parts, distance))


def _scored_lines(reference, extracted, domain, reference_all):
    """Scored reference, extracted and full reference lines, clipped to ``domain`` if given."""
    ref = _lines(reference)
    ext = _lines(extracted)
    ref_all = ref if reference_all is None else _lines(reference_all)
    if domain is not None:
        ref, ext, ref_all = (g.intersection(domain) for g in (ref, ext, ref_all))
    return ref, ext, ref_all


class NetworkScorer:
    """Thommeret lengths of any number of extracted networks against one reference.

    The reference lines are clipped to the domain once and the buffers of the full
    reference are kept per tolerance, so scoring many extracted networks (tolerances,
    sensitivity runs) repeats only the work that depends on the extracted lines.

    Parameters
    ----------
    reference, domain, reference_all
        As in :func:`network_validation`.
    """

    def __init__(self, reference, domain: BaseGeometry | None = None, reference_all=None) -> None:
        self.ref = _lines(reference)
        self.ref_all = self.ref if reference_all is None else _lines(reference_all)
        self.domain = domain
        if domain is not None:
            self.ref = self.ref.intersection(domain)
            self.ref_all = self.ref_all.intersection(domain)
        self._ref_buffers: dict[float, BaseGeometry] = {}

    @staticmethod
    def buffer(lines: BaseGeometry, tolerance_m: float) -> BaseGeometry:
        """The domain (buffer) of a line network, as used by :meth:`score`."""
        return _buffer(lines, tolerance_m)

    def clip(self, extracted: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry]) -> BaseGeometry:
        """The extracted lines as one geometry, clipped to the domain."""
        ext = _lines(extracted)
        return ext.intersection(self.domain) if self.domain is not None else ext

    def score(
        self,
        extracted: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
        tolerance_m: float,
        clipped: BaseGeometry | None = None,
        clipped_buffer: BaseGeometry | None = None,
    ) -> pd.DataFrame:
        """Rows ``reference, good_fit, false_positive, false_negative`` (see :func:`network_validation`).

        ``clipped`` (from :meth:`clip`) skips clipping ``extracted`` again, and
        ``clipped_buffer`` (:meth:`buffer` of ``clipped``) skips buffering it again.

        Parameters
        ----------
        extracted : lines
            The extracted network, CRS of the reference (m).
        tolerance_m : float
            Matching tolerance τ (m), at least 0.
        clipped : geometry or None
            ``extracted`` already clipped to the domain; None: clip it here.
        clipped_buffer : geometry or None
            Buffer of ``clipped`` by ``tolerance_m``; None: buffer it here.

        Returns
        -------
        DataFrame
            Columns ``category, length_m, percent``; ``percent`` is relative to the reference length
            (NaN when it is 0).
        """
        if tolerance_m < 0:
            raise ValueError(f"tolerance must be >= 0, got {tolerance_m}")
        ext = self.clip(extracted) if clipped is None else clipped
        l_ref = self.ref.length
        if ext.is_empty:
            good = 0.0
        else:
            ebuf = _buffer(ext, tolerance_m) if clipped_buffer is None else clipped_buffer
            good = self.ref.intersection(ebuf).length
        if self.ref_all.is_empty:
            fp = ext.length
        else:
            key = float(tolerance_m)
            if key not in self._ref_buffers:
                self._ref_buffers[key] = _buffer(self.ref_all, tolerance_m)
            fp = ext.difference(self._ref_buffers[key]).length
        fn = l_ref - good
        lengths = np.array([l_ref, good, fp, fn], dtype=float)
        percent = lengths / l_ref * 100.0 if l_ref > 0 else np.full(4, np.nan)
        return pd.DataFrame({"category": list(CATEGORIES), "length_m": lengths, "percent": percent})


def network_validation(
    reference: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    extracted: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    tolerance_m: float,
    domain: BaseGeometry | None = None,
    reference_all: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry] | None = None,
) -> pd.DataFrame:
    """Good fit, false positive and false negative lengths of an extracted network.

    Parameters
    ----------
    reference, extracted : lines
        The reference (field) network and the extracted network, same CRS (m).
    tolerance_m : float
        Matching tolerance τ (m): the domain of a network is its buffer of τ.
    domain : Polygon, optional
        Area where the comparison is made (e.g. the DEM footprint); both networks are
        clipped to it first.
    reference_all : lines, optional
        The whole reference network when ``reference`` is only its scored part (see
        :func:`scored_reference`): false positives are extracted lengths outside the
        domain of ``reference_all``. Default: ``reference``.

    Returns
    -------
    DataFrame
        Columns ``category, length_m, percent``, rows ``reference, good_fit,
        false_positive, false_negative``; ``percent`` is relative to the reference length
        (NaN when it is 0).

    Notes
    -----
    Complexity O((m + k) log(m + k)) for m, k line vertices (GEOS overlay). To score
    several networks or tolerances against one reference use :class:`NetworkScorer`.
    """
    if tolerance_m < 0:
        raise ValueError(f"tolerance must be >= 0, got {tolerance_m}")
    return NetworkScorer(reference, domain, reference_all).score(extracted, tolerance_m)


def validation_geometries(
    reference: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    extracted: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    tolerance_m: float,
    domain: BaseGeometry | None = None,
    reference_all: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry] | None = None,
) -> dict[str, BaseGeometry]:
    """The pieces behind :func:`network_validation`, for maps: ``good_fit``,
    ``false_negative`` (parts of the scored reference), ``false_positive`` (part of the
    extracted network) and ``not_scored`` (reference outside the scored part).

    Parameters
    ----------
    reference, extracted : lines
        The scored reference network and the extracted network, same CRS (m).
    tolerance_m : float
        Matching tolerance τ (m): the domain of a network is its buffer of τ.
    domain : Polygon or None
        Area where the comparison is made; all lines are clipped to it first.
    reference_all : lines or None
        The whole reference network; None: ``reference``.

    Returns
    -------
    dict of str to geometry
        Keys ``good_fit``, ``false_negative``, ``false_positive``, ``not_scored``.
    """
    ref, ext, ref_all = _scored_lines(reference, extracted, domain, reference_all)
    ext_dom = _buffer(ext, tolerance_m)
    ref_dom = _buffer(ref_all, tolerance_m)
    not_scored = ref_all.difference(ref.buffer(1e-6)) if not ref.is_empty else ref_all
    return {
        "good_fit": ref.intersection(ext_dom),
        "false_negative": ref.difference(ext_dom),
        "false_positive": ext.difference(ref_dom),
        "not_scored": not_scored,
    }


def _line_parts(geoms: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry]) -> list[shapely.LineString]:
    if isinstance(geoms, gpd.GeoDataFrame):
        geoms = geoms.geometry
    out = []
    for g in geoms:
        if g is None or g.is_empty:
            continue
        for part in getattr(g, "geoms", [g]):
            if part.geom_type == "LineString" and part.length > 0:
                out.append(part)
    return out


def scored_reference(
    reference: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    dem_domain: BaseGeometry,
    join_m: float,
    catchment: BaseGeometry | None = None,
) -> tuple[BaseGeometry, BaseGeometry, dict[str, int]]:
    """Split the reference network into the part that is scored and the part that is not.

    The paper scores only reference gullies inside the catchment whose heads fall within
    the area covered by the DEM (Feurer et al. 2018, Fig. 9b). [I] Reading of that rule:

    * every line runs downstream in vertex order (head first);
    * a line flows into the nearest other line within ``join_m`` of its downstream end,
      at the point of that line nearest to the end (lines are split there, so a
      tributary joining a channel mid-line drains only the channel below the junction);
      ends at the downstream end of another line do not count as junctions;
    * a head is the upstream end of a piece that nothing flows into;
    * a piece is scored when at least one head upstream of it lies within ``dem_domain``
      (the method traces from digitised heads, so this is the reference it can find);
      heads outside the DEM only feed pieces left out of the score;
    * with a catchment, the scored part is clipped to it.

    Parameters
    ----------
    reference : lines
        Reference (field) network, site CRS (m).
    dem_domain : Polygon
        Area covered by the DEM (its valid cells, :func:`footprint`).
    join_m : float
        Largest gap (m) between a line's downstream end and the line it flows into.
    catchment : Polygon, optional
        Catchment outline; ``None`` scores the whole DEM.

    Returns
    -------
    scored, not_scored : geometry
        Lines (MultiLineString or empty) of the two parts; their lengths add up to the
        reference length.
    counts : dict
        ``heads``, ``heads_on_dem``, ``pieces``, ``pieces_scored``.

    Notes
    -----
    Complexity O(m log m) for m lines (STRtree queries) plus the substring splits.
    """
    if join_m < 0:
        raise ValueError(f"join distance must be >= 0, got {join_m}")
    lines = _line_parts(reference)
    empty = shapely.MultiLineString()
    if not lines:
        return empty, empty, {"heads": 0, "heads_on_dem": 0, "pieces": 0, "pieces_scored": 0}
    lengths = np.array([ln.length for ln in lines])
    near_end = 1e-6 * max(1.0, float(lengths.max()))
    joins, splits = reference_joins(lines, join_m, near_end)
    pieces, piece_of, start_of = split_at_junctions(lines, splits, near_end)
    down, has_in = piece_graph(piece_of, start_of, joins, len(pieces), near_end)
    heads = np.flatnonzero(~has_in)
    head_pts = [shapely.Point(pieces[h].coords[0]) for h in heads]
    inside = np.array([dem_domain.covers(p) for p in head_pts], dtype=bool) if len(heads) else np.zeros(0, bool)
    scored = downstream_of(heads[inside], down)
    sc = shapely.union_all([pieces[k] for k in np.flatnonzero(scored)]) if scored.any() else empty
    ns = shapely.union_all([pieces[k] for k in np.flatnonzero(~scored)]) if (~scored).any() else empty
    if catchment is not None:
        outside = sc.difference(catchment)
        sc = sc.intersection(catchment)
        ns = shapely.union_all([ns, outside])
    counts = {
        "heads": int(len(heads)), "heads_on_dem": int(inside.sum()), "pieces": len(pieces), "pieces_scored": int(scored.sum())
    }
    return sc, ns, counts


def reference_joins(
    lines: list[shapely.LineString], join_m: float, near_end: float
) -> tuple[list[tuple[int, int, float]], list[list[float]]]:
    """Where every reference line flows into another (first phase of :func:`scored_reference`).

    Parameters
    ----------
    lines : list of LineString
        Reference lines, head first.
    join_m : float
        Largest gap (m) between a line's downstream end and the line it flows into.
    near_end : float
        Distances (m) this small count as "at the end" of a line.

    Returns
    -------
    joins : list of (from line, into line, distance along it)
        The nearest line within ``join_m`` of each downstream end, unless that end lies at
        the downstream end of the other line (then the other line is not downstream).
    splits : list of list of float
        Per line, the distances along it where tributaries join (cut points).
    """
    n = len(lines)
    lengths = np.array([ln.length for ln in lines])
    tree = shapely.STRtree(lines)
    ends = [shapely.Point(ln.coords[-1]) for ln in lines]
    joins: list[tuple[int, int, float]] = []  # (from line, into line, distance along it)
    splits: list[list[float]] = [[] for _ in range(n)]
    for i, e in enumerate(ends):
        best = None
        for j in tree.query(e, predicate="dwithin", distance=join_m):
            j = int(j)
            if j == i:
                continue
            d_along = lines[j].project(e)
            if d_along >= lengths[j] - near_end:
                continue  # ends at the downstream end of j: j is not downstream of i
            dist = lines[j].distance(e)
            if best is None or dist < best[0]:
                best = (dist, j, d_along)
        if best is not None:
            joins.append((i, best[1], best[2]))
            if best[2] > near_end:
                splits[best[1]].append(best[2])
    return joins, splits


def split_at_junctions(
    lines: list[shapely.LineString], splits: list[list[float]], near_end: float
) -> tuple[list[BaseGeometry], list[np.ndarray], list[np.ndarray]]:
    """Cut every line at its junctions (second phase of :func:`scored_reference`).

    Parameters
    ----------
    lines : list of LineString
        Reference lines, head first.
    splits : list of list of float
        Per line, the distances along it (m) where to cut (:func:`reference_joins`).
    near_end : float
        Pieces this short or shorter (m) are dropped.

    Returns
    -------
    pieces : list of LineString
        All pieces, line by line, upstream first; pieces shorter than ``near_end`` are dropped.
    piece_of : list of ndarray of int
        Piece ids of every line, upstream first.
    start_of : list of ndarray of float
        Distance of every piece's start along its line.
    """
    piece_of: list[np.ndarray] = []
    start_of: list[np.ndarray] = []
    pieces: list[BaseGeometry] = []
    for j, line in enumerate(lines):
        length = line.length
        cuts = np.unique(np.concatenate([[0.0], np.asarray(splits[j], dtype=float), [length]]))
        ids, st = [], []
        for a, b in zip(cuts[:-1], cuts[1:]):
            if b - a <= near_end:
                continue
            ids.append(len(pieces))
            st.append(a)
            pieces.append(substring(line, a, b))
        piece_of.append(np.asarray(ids, dtype=np.int64))
        start_of.append(np.asarray(st, dtype=float))
    return pieces, piece_of, start_of


def piece_graph(
    piece_of: list[np.ndarray],
    start_of: list[np.ndarray],
    joins: list[tuple[int, int, float]],
    n_pieces: int,
    near_end: float,
) -> tuple[list[list[int]], np.ndarray]:
    """Downstream links between pieces (third phase of :func:`scored_reference`).

    Each piece flows into the next piece of its line; the last piece of a line that joins
    another flows into the piece of that line starting at (or containing) the junction.

    Parameters
    ----------
    piece_of : list of ndarray of int
        Piece ids of every line, upstream first (:func:`split_at_junctions`).
    start_of : list of ndarray of float
        Distance (m) of every piece's start along its line.
    joins : list of (from line, into line, distance along it)
        Junctions from :func:`reference_joins`.
    n_pieces : int
        Number of pieces.
    near_end : float
        Tolerance (m) added to a junction's distance when finding the piece it falls on.

    Returns
    -------
    down : list of list of int
        Pieces directly downstream of every piece.
    has_in : ndarray of bool
        Whether anything flows into a piece (pieces without inflow start at a head).
    """
    down: list[list[int]] = [[] for _ in range(n_pieces)]
    has_in = np.zeros(n_pieces, dtype=bool)
    for p in piece_of:
        for a, b in zip(p[:-1], p[1:]):
            down[a].append(int(b))
            has_in[b] = True
    for i, j, d_along in joins:
        if piece_of[i].size == 0 or piece_of[j].size == 0:
            continue
        # the piece of j that starts at (or contains) the junction
        k = int(piece_of[j][max(0, int(np.searchsorted(start_of[j], d_along + near_end, side="right")) - 1)])
        down[int(piece_of[i][-1])].append(k)
        has_in[k] = True
    return down, has_in


def downstream_of(start: np.ndarray, down: list[list[int]]) -> np.ndarray:
    """Boolean mask of the pieces reached from ``start`` (included) along ``down`` (last phase). O(pieces + links)."""
    reached = np.zeros(len(down), dtype=bool)
    stack = [int(h) for h in start]
    for h in stack:
        reached[h] = True
    while stack:
        a = stack.pop()
        for b in down[a]:
            if not reached[b]:
                reached[b] = True
                stack.append(b)
    return reached


def rasterize_polygons(polygons: gpd.GeoDataFrame | Iterable[BaseGeometry], grid: GridSpec) -> np.ndarray:
    """Boolean mask of the cells whose centre falls in any polygon. O(n)."""
    geoms = list(polygons.geometry if isinstance(polygons, gpd.GeoDataFrame) else polygons)
    geoms = [g for g in geoms if g is not None and not g.is_empty]
    if not geoms:
        return np.zeros((grid.height, grid.width), dtype=bool)
    out = rasterio.features.rasterize(
        [(g, 1) for g in geoms], out_shape=(grid.height, grid.width), transform=grid.transform, fill=0, dtype="uint8"
    )
    return out.astype(bool)


def footprint(
    valid: np.ndarray,
    grid: GridSpec,
    near: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry] | None = None,
    margin_cells: int = 2,
) -> BaseGeometry:
    """Polygon of the valid cells of a raster (the DEM footprint). O(n).

    With ``near`` (lines, e.g. the reference and the traced network) only the valid cells
    within ``margin_cells`` of those lines are polygonised: clipping those lines to this
    polygon gives exactly what clipping them to the whole footprint gives (the lines lie
    at least ``margin_cells`` inside its artificial border), at a fraction of the cost on a
    large DEM.

    Parameters
    ----------
    valid : ndarray (H, W) bool
        Valid cells of the raster.
    grid : GridSpec
        Grid of ``valid``.
    near : lines or None
        Lines to keep the polygon near; None: polygonise all valid cells.
    margin_cells : int
        Half-width (cells) of the band around ``near`` that is polygonised.

    Returns
    -------
    geometry
        Union of the polygonised cells (empty Polygon when there are none).
    """
    valid = np.asarray(valid, dtype=bool)
    if near is not None:
        shapes = [g for g in _line_parts(near)]
        band = np.zeros(valid.shape, dtype=bool)
        if shapes:
            band = rasterio.features.rasterize(
                [(g, 1) for g in shapes], out_shape=valid.shape, transform=grid.transform, fill=0, all_touched=True,
                dtype="uint8",
            ).astype(bool)
            band = cv2.dilate(band.astype(np.uint8), np.ones((2 * margin_cells + 1,) * 2, np.uint8)).astype(bool)
        valid = valid & band
    valid = valid.astype(np.uint8)
    polys = [shapely.geometry.shape(g) for g, v in rasterio.features.shapes(valid, mask=valid > 0, transform=grid.transform) if v]
    return shapely.union_all(polys) if polys else shapely.Polygon()


def area_scores(predicted: np.ndarray, truth: np.ndarray, cell_m: float) -> dict[str, float]:
    """Cell-wise precision, recall and IoU of a predicted gully mask against the truth mask.

    Returns a dict with ``predicted_area_m2``, ``truth_area_m2``, ``intersection_m2``,
    ``precision``, ``recall``, ``iou`` (NaN where a denominator is 0).

    Parameters
    ----------
    predicted, truth : ndarray (H, W) bool
        Predicted and true gully masks on the same grid.
    cell_m : float
        Cell size (m).

    Returns
    -------
    dict of str to float
        The areas (m²) and the scores listed above.
    """
    predicted = np.asarray(predicted, dtype=bool)
    truth = np.asarray(truth, dtype=bool)
    if predicted.shape != truth.shape:
        raise ValueError(f"mask shapes differ: {predicted.shape} vs {truth.shape}")
    a = cell_m**2
    tp = float(np.count_nonzero(predicted & truth)) * a
    p = float(np.count_nonzero(predicted)) * a
    t = float(np.count_nonzero(truth)) * a
    union = p + t - tp
    return {
        "predicted_area_m2": p,
        "truth_area_m2": t,
        "intersection_m2": tp,
        "precision": tp / p if p else float("nan"),
        "recall": tp / t if t else float("nan"),
        "iou": tp / union if union else float("nan"),
    }
