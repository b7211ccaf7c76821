"""Reruns of the same config give the same numbers: the tiny twin's SfM twice (sfm.deterministic)."""

from __future__ import annotations

import pytest

from .tiny_sfm import copy_results, run_sfm, sfm_tables

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("tiny_sfm")]


def test_sfm_rerun_gives_identical_tables(tiny_flight, sfm_reference, tmp_path):
    results = copy_results(tiny_flight, tmp_path / "results")
    run_sfm(results)
    again = sfm_tables(results)
    assert again["summary.json"]["deterministic"] is True and again["summary.json"]["threads"] == 1
    assert again["summary.json"]["n_registered"] == again["summary.json"]["n_images"] == 12
    assert set(again) == set(sfm_reference)
    for name in sfm_reference:
        assert again[name] == sfm_reference[name], f"{name} differs between two runs of the same config"
