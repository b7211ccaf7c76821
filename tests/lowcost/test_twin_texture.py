"""The low-cost twin's texture, made with little memory, is the whole-array texture, and the
5 mm site variant gives the paper's pixel."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from kitegully.config import load_yaml, merge_config, validate_config
from kitegully.lowcost.twin_site import (BANDS, CLASS_CODES, LowcostTwinParams, _noise, flight_poses, make_camera,
                                         make_ground, make_texture, target_layout)
from kitegully.seeds import rng_for

ROOT = Path(__file__).resolve().parents[2]
BASE, FIVE = ROOT / "config/sites/lowcost_twin.yaml", ROOT / "config/sites/variants/lowcost_twin_5mm.yaml"


def _reference_texture(p, grid, cls, targets, seed):
    """The texture as first written (whole float arrays): the reference the chunked one must equal."""
    def noise(rng, shape, s):
        n = ndimage.gaussian_filter(rng.standard_normal(shape), s, mode="wrap")
        return (n - n.mean()) / max(n.std(), 1e-12)

    k = max(1, int(round(grid.cell / p.texture_cell_m)))
    tc = grid.cell / k
    big = np.repeat(np.repeat(cls, k, axis=0), k, axis=1)
    rng = rng_for(seed, "lowcost", "texture")
    shape = big.shape
    bright = np.exp(0.25 * noise(rng, shape, 1.5) + 0.2 * noise(rng, shape, 6.0) + 0.15 * noise(rng, shape, 25.0))
    water = big == CLASS_CODES["water"]
    bright[water] = np.exp(0.08 * noise(rng, shape, 3.0))[water]
    tex = np.zeros((4,) + shape, np.float32)
    for name, code in CLASS_CODES.items():
        m = big == code
        for b, band in enumerate(BANDS):
            tex[b][m] = p.classes[name][band]
    tex *= bright[None]
    half = p.target_panel_m / 2
    for xy in targets.values():
        c0 = int((xy[0] - half - grid.x0) / tc)
        r0 = int((grid.y0 - (xy[1] + half)) / tc)
        n = int(round(p.target_panel_m / tc))
        rr, cc = np.mgrid[0:n, 0:n]
        tex[:, r0:r0 + n, c0:c0 + n] = np.where((rr < n // 2) ^ (cc < n // 2), 0.8, 0.04)[None]
    return np.clip(np.rint(tex * 255.0), 0, 255).astype(np.uint8), tc


@pytest.fixture(scope="module")
def small():
    cfg = dict(load_yaml(BASE)["lowcost"]["twin"])
    cfg.update(length_m=8.0, width_m=5.0, dsm_cell_m=0.05, texture_cell_m=0.0125)
    return LowcostTwinParams.from_config(cfg)


def test_noise_in_place_equals_filtering_a_copy():
    a = _noise(np.random.default_rng(5), (60, 70), 3.0)
    n = ndimage.gaussian_filter(np.random.default_rng(5).standard_normal((60, 70)), 3.0, mode="wrap")
    assert np.array_equal(a, (n - n.mean()) / n.std())


def test_texture_equals_the_whole_array_texture(small):
    grid, _, _, cls = make_ground(small, 7)
    t = target_layout(small, 7)
    ref, tc_ref = _reference_texture(small, grid, cls, t, 7)
    for chunk in (1024, 37):                                       # the chunk changes nothing
        tex, tc = make_texture(small, grid, cls, t, 7, chunk_rows=chunk)
        assert tc == tc_ref and tex.dtype == np.uint8
        assert np.array_equal(tex, ref)
    assert (ref == 204).any() and (ref == 10).any()               # the checkerboards are painted


def test_5mm_variant_has_the_paper_pixel_and_flight():
    base = load_yaml(BASE)
    cfg = merge_config(base, load_yaml(FIVE))
    validate_config(merge_config(load_yaml(ROOT / "config/config.yaml"), cfg), sources=[BASE, FIVE])
    p = LowcostTwinParams.from_config(cfg["lowcost"]["twin"])
    cam = make_camera(p.camera, "NEX-5")
    assert (cam.width, cam.height) == (4912, 3264)                  # 16 MP [P]
    assert cam.gsd(15.0) == pytest.approx(0.0045, abs=1e-4)         # the paper's 4.5 mm at 15 m
    assert cam.gsd(16.5) == pytest.approx(0.0049, abs=1e-4)         # mean of 15-18 m: ~5 mm
    assert p.texture_cell_m == pytest.approx(cam.gsd(16.5) / 2, rel=0.05)
    # same ground and flights as the 1.95 cm site: only the pixel count differs
    p0 = LowcostTwinParams.from_config(base["lowcost"]["twin"])
    assert (p.length_m, p.width_m, p.flight, p.classes) == (p0.length_m, p0.width_m, p0.flight, p0.classes)
    assert len(flight_poses(p, "rgb", 1, 0.0)) == len(flight_poses(p0, "rgb", 1, 0.0)) == 28
    s = cfg["lowcost"]["survey"]
    assert s["dsm_cell_m"] == 0.025 and s["dsm_cell_m"] / s["ortho_upsample"] == pytest.approx(0.005)   # [P] 2.5 cm, 5 mm
    assert cfg["site"]["name"] == "lowcost_twin_5mm" and cfg["lowcost"]["sfm"] == base["lowcost"]["sfm"]


def test_override_files_merge_key_by_key_as_snakemake():
    base = {"a": {"b": 1, "c": {"d": 2, "e": [1, 2]}}, "f": 3}
    out = merge_config(base, {"a": {"c": {"e": [9]}}, "g": 4})
    assert out == {"a": {"b": 1, "c": {"d": 2, "e": [9]}}, "f": 3, "g": 4}
    assert base["a"]["c"]["e"] == [1, 2]                           # the base is not changed
    from kitegully.config import main
    assert main([str(BASE), str(FIVE)]) == 0                        # what make lowcost-5mm checks first
