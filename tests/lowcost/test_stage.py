"""The low-cost survey's own checks: NIR photos with a red channel, the survey section's keys."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from kitegully import InputError
from kitegully.lowcost.stage import SurveyParams, check_nir_images


def test_nir_photo_without_a_red_channel_is_one_sentence(tmp_path):
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "rgb_000.jpg")
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "nir_000.jpg")
    check_nir_images(tmp_path)
    Image.fromarray(np.zeros((8, 8), np.uint8)).save(tmp_path / "nir_001.jpg")
    with pytest.raises(InputError, match=r"nir_001\.jpg: NIR photo has no red channel \(mode L, 1 band\)"):
        check_nir_images(tmp_path)


def _survey_cfg(**kw):
    cfg = {"gamma": 2.2, "dsm_cell_m": 0.1, "ortho_upsample": 5, "min_track_length": 3, "occlusion_tolerance_m": 0.1,
           "level_to_water": True, "waterline_min_spread_m": 1.0, "dsm_method": "tin"}
    return {**cfg, **kw}


def test_survey_dsm_method_and_dense_section_are_checked():
    assert SurveyParams.from_config(_survey_cfg()).dense is None
    matching = {"levels": 3, "window_half_cells": 2, "z_step_cells": 0.5, "refine_radius_steps": 3, "max_labels": 96,
                "z_margin_m": 0.5, "p1": 0.02, "p2": 0.12, "sgm_directions": 8, "min_correlation": 0.3, "min_views": 2,
                "min_std_dn": 3.0, "nan_cost": 1.0, "final_passes": 1}
    dense = {"tile_cells": 256, "overlap_cells": 16, "max_cached_images": 28, "matching": matching}
    p = SurveyParams.from_config(_survey_cfg(dsm_method="dense", dense=dense))
    assert p.dense["matching"].levels == 3 and p.dense["tile_cells"] == 256
    with pytest.raises(InputError, match="lowcost.survey.dsm_method: must be tin or dense, got 'pmvs'"):
        SurveyParams.from_config(_survey_cfg(dsm_method="pmvs"))
    with pytest.raises(InputError, match="lowcost.survey.dense: dsm_method dense needs the dense section"):
        SurveyParams.from_config(_survey_cfg(dsm_method="dense"))
    with pytest.raises(InputError, match="lowcost.survey.dense.matching"):
        SurveyParams.from_config(_survey_cfg(dsm_method="dense", dense={**dense, "matching": {"levels": 3}}))
