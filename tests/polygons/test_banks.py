"""Depth reference from the banks (``reference: banks`` / ``bank_lines``): the pre-incision surface across a gully."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from kitegully import InputError
from kitegully.io.raster import GridSpec
from kitegully.polygons.conditioning import polygons_from_labels
from kitegully.polygons.morphometry import _bank_drape, measure_sections
from kitegully.polygons.profiles import bank_reference, section_profile
from kitegully.polygons.stage import PolygonParams

from .polygon_synthetic import CRS, true_area

FIT = 4.5


def _profile(surface: str, shape: str, width: float = 6.0, depth: float = 1.5, c: float = 0.04, k: float = 0.01):
    """A section 0..B between reference ends 0.75 m outside the edges, prolonged by FIT: (s, z, z0, B, axis)."""
    B = width + 1.5
    s = np.arange(-FIT, B + FIT + 1e-9, 0.25)
    m = 0.5 * B
    d = np.abs(s - m)
    z0 = {"plane": 100.0 + c * s, "valley": 100.0 + c * d, "hollow": 100.0 + k * d**2}[surface]
    h = 0.5 * width
    p = 1.0 if shape == "V" else 4.0
    return s, z0 - np.where(d < h, depth * (1.0 - (d / h) ** p), 0.0), z0, B, m


@pytest.mark.parametrize("shape", ["V", "U"])
def test_on_a_tilted_plane_both_bank_models_are_the_straight_line(shape):
    s, z, z0, B, _ = _profile("plane", shape)
    inner = (s >= 0) & (s <= B)
    for model in ("quadratic", "lines"):
        zr = bank_reference(s, z, B, FIT, model)
        assert np.abs(zr - z0[inner]).max() < 1e-9
        dep, area = section_profile(s[inner], z[inner], "banks", zr)
        dl, al = section_profile(s[inner], z[inner], "line")
        assert dep == pytest.approx(1.5, abs=1e-9) and dep == pytest.approx(dl) and area == pytest.approx(al)
        assert area == pytest.approx(true_area(shape, 6.0, 1.5), rel=0.01)


@pytest.mark.parametrize("shape", ["V", "U"])
def test_in_a_hollow_the_parabola_is_exact_and_the_line_too_deep(shape):
    k = 0.01
    s, z, z0, B, m = _profile("hollow", shape, k=k)
    inner = (s >= 0) & (s <= B)
    zr = bank_reference(s, z, B, FIT, "quadratic")
    assert np.abs(zr - z0[inner]).max() < 1e-9
    dep, area = section_profile(s[inner], z[inner], "banks", zr)
    assert dep == pytest.approx(1.5, abs=1e-9)
    dl, _ = section_profile(s[inner], z[inner], "line")
    assert dl == pytest.approx(1.5 + k * (0.5 * B) ** 2, abs=1e-9)  # the chord stands k (B/2)^2 above the hollow's floor
    # two bank lines, each extrapolated from a lever arm outside the gully, fall below the hollow's floor
    dlines, _ = section_profile(s[inner], z[inner], "bank_lines", bank_reference(s, z, B, FIT, "lines"))
    assert dlines < 1.5 - 0.05


@pytest.mark.parametrize("shape", ["V", "U"])
def test_in_a_v_shaped_valley_floor_lines_are_exact_and_the_parabola_between(shape):
    c = 0.04
    s, z, z0, B, m = _profile("valley", shape, c=c)
    inner = (s >= 0) & (s <= B)
    dl, _ = section_profile(s[inner], z[inner], "line")
    assert dl == pytest.approx(1.5 + c * 0.5 * B, abs=1e-9)  # the chord stands c B/2 above the valley's V
    dlines, _ = section_profile(s[inner], z[inner], "bank_lines", bank_reference(s, z, B, FIT, "lines"))
    assert dlines == pytest.approx(1.5, abs=1e-9)
    dq, _ = section_profile(s[inner], z[inner], "banks", bank_reference(s, z, B, FIT, "quadratic"))
    assert 1.5 < dq < dl - 0.15 * c * 0.5 * B  # takes a part (here ~1/4) of the chord's excess, never below the truth


def test_a_bank_without_data_falls_back_to_the_straight_line():
    s, z, _, B, _ = _profile("hollow", "U")
    z = z.copy()
    z[s < 0] = np.nan
    inner = (s >= 0) & (s <= B)
    chord = z[inner][0] + (z[inner][-1] - z[inner][0]) * s[inner] / B
    for model in ("quadratic", "lines"):
        assert np.allclose(bank_reference(s, z, B, FIT, model), chord)
    with pytest.raises(ValueError, match="model"):
        bank_reference(s, z, B, FIT, "cubic")


def _hollow_notch(shape: str, width: float = 6.0, depth: float = 1.5, k: float = 0.01, cell: float = 0.5):
    """A straight notch along y cut into a hollow 100 + k d^2 that falls 0.02 along y; axis on a cell centre."""
    grid = GridSpec(500000.0, 4000000.0, cell, 120, 200, CRS)
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs, ys)
    xc = float(xs[60])
    d = np.abs(x - xc)
    h = 0.5 * width
    p = 1.0 if shape == "V" else 4.0
    z = 100.0 + 0.02 * (y - ys.min()) + k * d**2 - np.where(d < h, depth * (1.0 - (d / h) ** p), 0.0)
    return z.astype(np.float32), grid, xc


@pytest.mark.parametrize("shape", ["V", "U"])
def test_sections_with_the_bank_reference_recover_a_notch_in_a_hollow(shape):
    W, D, k = 6.0, 1.5, 0.01
    dem, grid, xc = _hollow_notch(shape, W, D, k)
    xs, _ = grid.cell_centres()
    lab = np.zeros(dem.shape, np.int32)
    lab[20:180, :] = (np.abs(xs - xc) <= 0.5 * W - 0.5)[None, :]  # a polygon at fill depth t ends inside the rims
    polys = polygons_from_labels(lab, grid, 0.5)
    rims = np.zeros(dem.shape, bool)
    rims[:, np.abs(np.abs(xs - xc) - 0.5 * W) < 0.3] = True  # the breakline on the true edge (its band's middle)
    args = (lab, polys, dem, dem, grid, 10.0)
    kw = dict(branches="all", rims=rims, rim_search_m=4.5, ground_segment_m=4.0)
    _, s_line, _ = measure_sections(*args, "line", 2.0, 1.0, 1.0, **kw)
    _, s_bank, m_bank = measure_sections(*args, "banks", 2.0, 1.0, 1.0, bank_fit_m=FIT, **kw)
    assert len(s_bank) >= 7
    # within a cell's rise of the hollow at the edge (k x cell x W) of the truth; the line is too deep by ~k (W/2)^2
    assert np.abs(s_bank["depth_m"] - D).max() <= k * 0.5 * W + 0.02
    assert np.median(s_line["depth_m"]) - D >= 0.5 * k * (0.5 * W) ** 2
    assert np.median(s_bank["area_m2"]) == pytest.approx(true_area(shape, W, D), rel=0.06)
    assert np.median(s_line["area_m2"]) > np.median(s_bank["area_m2"]) + 0.5 * k * W**3 / 6  # the hollow's lens k W^3/6
    assert np.allclose(s_bank["width_m"], s_line["width_m"])  # width is the clipped length, untouched
    assert m_bank["volume_m3"].iloc[0] == pytest.approx((s_bank["area_m2"] * s_bank["slab_m"]).sum())


def test_bank_reference_needs_a_bank_length():
    with pytest.raises(InputError, match=r"^polygons.morphometry.bank_fit_m: reference 'banks' needs a bank length > 0 \(m\), got 0.0$"):
        PolygonParams(reference="banks")
    assert PolygonParams(reference="banks", bank_fit_m=4.5).bank_fit_m == 4.5


def _tilted_notch(shape: str, width: float = 6.0, depth: float = 1.5, cross: float = 0.05, cell: float = 0.5):
    """A straight notch along y in a plane rising at ``cross`` towards +x (so the field falls away west of it, rises east)."""
    grid = GridSpec(500000.0, 4000000.0, cell, 120, 200, CRS)
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs, ys)
    xc = float(xs[60])
    d = np.abs(x - xc)
    h = 0.5 * width
    p = 1.0 if shape == "V" else 4.0
    z = 100.0 + 0.02 * (y - ys.min()) + cross * (x - xc) - np.where(d < h, depth * (1.0 - (d / h) ** p), 0.0)
    return z.astype(np.float32), grid, xc


@pytest.mark.parametrize("shape", ["V", "U"])
def test_an_end_without_a_rim_goes_to_the_highest_ground_not_the_outline(shape):
    W, D = 6.0, 1.5
    dem, grid, xc = _tilted_notch(shape, W, D)
    xs, _ = grid.cell_centres()
    lab = np.zeros(dem.shape, np.int32)
    lab[20:180, :] = (np.abs(xs - xc) <= 0.5 * W - 0.75)[None, :]  # the outline 0.75 m inside both edges
    polys = polygons_from_labels(lab, grid, 0.5)
    no_rims = np.zeros(dem.shape, bool)  # the breakline test marked no upper edge on either side
    args = (lab, polys, dem, dem, grid, 10.0, "banks", 2.0, 1.0, 1.0)
    kw = dict(branches="all", rims=no_rims, rim_search_m=4.5, ground_segment_m=0.0, bank_fit_m=FIT)  # a DTM
    _, s_out, _ = measure_sections(*args, **kw)
    _, s_hi, _ = measure_sections(*args, no_rim="highest_ground", **kw)
    # with the 4 m ground opening (a DSM) the west rim, whose field falls away, is read low by at most
    # cross slope x segment (the opening's stated limit, test_ground.py)
    _, s_hi_g, _ = measure_sections(*args, no_rim="highest_ground", **{**kw, "ground_segment_m": 4.0})
    assert np.all((s_hi_g["depth_m"] <= D + 0.02) & (s_hi_g["depth_m"] >= D - 0.05 * 4.0))
    # on the outline the reference stands on the walls: too shallow, and the walls' area is lost
    assert np.median(s_out["depth_m"]) < D - 0.1
    assert np.median(s_out["area_m2"]) < 0.85 * true_area(shape, W, D)
    # west the field falls away: the highest ground is the edge itself; east it rises: the end goes the whole
    # search, onto the field, which the bank parabola (= the plane) follows, so it adds nothing
    assert np.abs(s_hi["depth_m"] - D).max() <= 0.05
    assert np.median(s_hi["area_m2"]) == pytest.approx(true_area(shape, W, D), rel=0.05)
    ref = s_hi["reference_length_m"].to_numpy()
    assert np.all(ref >= W - 0.5) and np.all(ref <= W - 1.5 + 4.5 + 0.5 + 0.75)
    assert np.allclose(s_hi["width_m"], s_out["width_m"])  # width stays the clipped length


def test_no_rim_setting_is_checked():
    with pytest.raises(InputError, match=r"^polygons.morphometry.no_rim: must be one of \('outline', 'highest_ground'\), got 'field'$"):
        PolygonParams(no_rim="field")


def test_the_bank_reference_has_one_value_per_section_sample_on_grid_aligned_sections():
    # Sections whose ends lie on the quarter-metre lattice of the polygon outlines: rounding put a
    # sample of the prolonged drape within 1e-9 m beyond an end, counted as bank and as section
    # (held-out twin h5 stopped on "operands could not be broadcast together with shapes (37,) (36,)").
    grid = GridSpec(0.0, 100.0, 0.5, 200, 200, "EPSG:32632")
    dem = np.random.default_rng(0).normal(0.0, 0.1, (200, 200))
    rng = np.random.default_rng(1)
    for _ in range(3000):
        a = np.round(rng.uniform(30, 70, 2) * 4) / 4
        b = a + np.round(rng.uniform(-10, 10, 2) * 4) / 4
        if np.allclose(a, b):
            continue
        s, z, ref = _bank_drape(shapely.LineString([a, b]), dem, grid, 0.25, 4.0, 4.5, "quadratic")
        assert len(s) == len(z) == len(ref)
