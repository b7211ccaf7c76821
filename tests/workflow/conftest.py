"""Session fixtures of the workflow rerun tests (tiny twin photos, one reference SfM run)."""

from __future__ import annotations

import pytest

from .tiny_sfm import copy_results, flight_photos, run_sfm, sfm_tables


@pytest.fixture(scope="session")
def tiny_flight(tmp_path_factory):
    """A results folder holding the tiny twin's flight photos (twin + flight stages run once)."""
    return flight_photos(tmp_path_factory.mktemp("tiny_flight") / "results")


@pytest.fixture(scope="session")
def sfm_reference(tiny_flight, tmp_path_factory):
    """Tables of one uninterrupted SfM run on a copy of ``tiny_flight``."""
    results = copy_results(tiny_flight, tmp_path_factory.mktemp("sfm_reference") / "results")
    run_sfm(results)
    return sfm_tables(results)
