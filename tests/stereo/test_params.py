"""Parameters of the stereo stage: the site file reads, bad keys give one sentence."""

import copy

import pytest

from kitegully import InputError
from kitegully.stereo import StereoParams


def test_params_from_site_file_and_bad_keys(cfg):
    p = StereoParams.from_config(cfg)
    assert p.calibration["field_sigma_mm"] == 0.2 and len(p.dry_box["setups"]) == 11
    bad = copy.deepcopy(cfg)
    bad["rain"]["drop_size"] = 2
    with pytest.raises(InputError, match="stereo.rain: unknown key 'drop_size'"):
        StereoParams.from_config(bad)
    bad = copy.deepcopy(cfg)
    bad["rain"]["bulk_densities"] = [0.91, 1.3]
    with pytest.raises(InputError, match=r"stereo.rain.bulk_densities: 1.3 g/cm³ must lie between 0 and seal_density \(1.2\)"):
        StereoParams.from_config(bad)
    bad = copy.deepcopy(cfg)
    bad["calibration"]["stations"] = "many"
    with pytest.raises(InputError, match="stereo.calibration.stations: must be one of paper, paper\\+convergent, paper\\+convergent\\+corners"):
        StereoParams.from_config(bad)
