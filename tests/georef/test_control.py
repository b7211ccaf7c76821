"""QA of the georeferencing run on a synthetic block: flags, outliers, leave-one-out, errors.

Built on the synthetic block of tests/georef/test_bundle.py (GSD 0.05 m, tie noise 0.3 px, GCP
pixel noise 0.5 px, survey noise 0.01 m), here without a dome.
"""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.georef.gcp_io import GCP
from kitegully.georef.geometry import project, rotvec_to_matrix, triangulate, triangulation_covariance
from kitegully.georef import GeorefParams, georeference_block
from kitegully.sfm.images import ImageInfo
from georef.test_bundle import GSD, synthetic_block

PARAMS = {
    "gcp_format": "odm",
    "csv_crs": None,
    "tape_file": None,
    "max_tie_points": 0,
    "tie_grid": None,
    "figure": {"arrow_scale": None},
    "cloud_format": "laz",
    "method": "gcp_bundle",
    "gcp_pixel_frame": "stored",
    "gcp_pixel_scale": 1.0,
    "gcp_pixel_offset_px": 0.0,
    "sigma_gcp_xy_m": 0.01,
    "sigma_gcp_z_m": 0.01,
    "qa": {"max_triangulation_px": 3.0, "max_residual_m": 0.25, "coords_tolerance_m": 0.05,
           "min_gcps_trusted": 4, "required_accuracy_m": 2 * GSD},
    "bundle": {"sigma_tie_px": 0.3, "sigma_gcp_px": 0.5, "refine_intrinsics": ["f", "k1", "k2"], "loss": "huber",
               "loss_scale": 3.0, "max_iterations": 30, "rel_tolerance": 1e-6},
}


def georeference(model, gcps, infos, rows, cfg, sfm_frame, tape_edges=None):
    """The block-level georeferencing with parameters built from a ``georef`` section."""
    return georeference_block(model, gcps, infos, rows, GeorefParams.from_config(cfg), sfm_frame, tape_edges)


def _setup(displace_pixel=None, displace_survey=None, drop=()):
    model, survey, G, C, _ = synthetic_block(dome=0.0, k1_start=-0.05)
    names = [f"img_{i:02d}.jpg" for i in range(len(model.rv))]
    infos = [ImageInfo(n, n, 1, 1600, 1200, 1600, 1200, 1.0, "", 1200.0) for n in names]
    rows = {n: i for i, n in enumerate(names)}
    gcps = []
    for g in range(len(survey)):
        sel = model.gcp_obs_gcp == g
        px = model.gcp_obs_xy[sel].copy()
        if displace_pixel and displace_pixel[0] == g:
            px[0] += displace_pixel[1]
        xyz = survey[g].copy() + [340000.0, 5500000.0, 0.0]
        if displace_survey and displace_survey[0] == g:
            xyz += displace_survey[1]
        imgs = [names[i] for i in model.gcp_obs_image[sel]]
        if g in drop:
            imgs, px = imgs[:1], px[:1]
        gcps.append(GCP(f"T{g}", xyz, imgs + ["absent.jpg"], np.vstack([px, [[10.0, 10.0]]])))
    return model, gcps, infos, rows


def test_clean_block_meets_gsd_targets_and_is_trusted():
    model, gcps, infos, rows = _setup()
    r = georeference(model, gcps, infos, rows, PARAMS, "stored")
    res = r.residuals
    assert res["used"].all()
    assert np.sqrt(np.mean(res["dx_m"] ** 2 + res["dy_m"] ** 2)) <= GSD
    assert np.sqrt(np.mean(res["dz_m"] ** 2)) <= 1.5 * GSD
    assert r.report["loo_rmse_3d_m"] <= 2 * GSD
    assert len(r.loo) == len(gcps) and r.loo["flag"].str.contains("checkpoint").all()
    assert res["flag"].str.contains("missing_images:1").all()
    assert r.report["trusted"], r.report["trust_reasons"]


def test_displaced_observation_is_flagged_and_left_out():
    # 25 px on one of a GCP's observations: its rays no longer meet (threshold 3 px)
    model, gcps, infos, rows = _setup(displace_pixel=(2, [25.0, -10.0]))
    PARAMS2 = {**PARAMS, "method": "similarity"}
    r = georeference(model, gcps, infos, rows, PARAMS2, "stored")
    row = r.residuals.set_index("gcp_id").loc["T2"]
    assert "ray_miss" in row["flag"] and not row["used"]
    assert r.residuals.drop(index=2)["used"].all()


def test_displaced_survey_is_an_outlier_and_does_not_spoil_the_rest():
    model, gcps, infos, rows = _setup(displace_survey=(4, np.array([1.5, -1.0, 0.5])))
    r = georeference(model, gcps, infos, rows, {**PARAMS, "method": "similarity"}, "stored")
    res = r.residuals.set_index("gcp_id")
    assert "outlier" in res.loc["T4", "flag"] and not res.loc["T4", "used"]
    assert res.loc["T4", "d3_m"] > 1.0  # its true misfit (1.9 m) is reported
    others = res.drop(index="T4")
    assert others["used"].all() and others["d3_m"].max() < 0.25
    assert not r.report["trusted"]


def test_moderately_displaced_survey_is_flagged_poor_fit_but_kept():
    # 0.1 m (2 GSD) in easting: below the 0.25 m outlier limit, so the GCP stays in the
    # solution, but its leave-one-out misfit is far beyond what its survey (0.01 m), its
    # clicks through its own rays and the block's placement explain
    model, gcps, infos, rows = _setup(displace_survey=(3, np.array([0.1, 0.0, 0.0])))
    r = georeference(model, gcps, infos, rows, PARAMS, "stored")
    res = r.residuals.set_index("gcp_id")
    assert "poor_fit" in res.loc["T3", "flag"] and res.loc["T3", "used"]
    assert not res.drop(index="T3")["flag"].str.contains("poor_fit").any()
    assert not r.report["trusted"] and "T3" in " ".join(r.report["trust_reasons"])


def test_single_observation_and_too_few_gcps():
    model, gcps, infos, rows = _setup(drop=(0, 1, 2, 3, 4))
    with pytest.raises(InputError, match="fewer than three usable GCPs") as err:
        georeference(model, gcps, infos, rows, PARAMS, "stored")
    assert "T0 (missing_images:1;single_obs)" in str(err.value)
    model, gcps, infos, rows = _setup(drop=(0,))
    r = georeference(model, gcps, infos, rows, {**PARAMS, "method": "similarity"}, "stored")
    assert "single_obs" in r.residuals.loc[0, "flag"] and not r.residuals.loc[0, "used"]


def test_tape_horn_method_takes_scale_from_the_tape_not_the_gps():
    """Paper 004's variant: GPS positions with ±2 m noise, taped distances exact."""
    model, gcps, infos, rows = _setup()
    truth = [g.xyz.copy() for g in gcps]
    rng = np.random.default_rng(9)
    for g in gcps:
        g.xyz = g.xyz + rng.normal(0, 2.0, 3)
    edges = [(gcps[i].gcp_id, gcps[j].gcp_id, float(np.linalg.norm(truth[i] - truth[j]))) for i, j in ((0, 1), (1, 2), (2, 0), (3, 4), (4, 6))]
    r = georeference(model, gcps, infos, rows, {**PARAMS, "method": "tape_horn", "tape_file": "tape.csv"}, "stored", tape_edges=edges)
    # distances between GCPs in the result equal the taped ones to the image precision (~1 GSD)
    X = np.array([r.residuals.loc[k, ["dx_m", "dy_m", "dz_m"]].to_numpy(float) for k in range(len(gcps))])
    est = X + np.array([g.xyz for g in gcps])  # triangulated positions in the site CRS
    for a, b, d in edges:
        ia, ib = int(a[1:]), int(b[1:])
        assert np.linalg.norm(est[ia] - est[ib]) == pytest.approx(d, abs=2 * GSD)
    assert r.report["method"] == "tape_horn"


def _nadir_cameras(centres):
    rv = np.tile([np.pi, 0.0, 0.0], (len(centres), 1))  # looking straight down
    R = rotvec_to_matrix(rv)
    t = -np.einsum("nij,nj->ni", R, centres)
    intr = np.tile([1000.0, 800.0, 600.0, -0.05, 0.01], (len(centres), 1))
    return intr, rv, t


@pytest.mark.parametrize("baseline_m", [10.0, 40.0])
def test_triangulation_covariance_matches_monte_carlo(baseline_m):
    # 4 nadir views from 100 m; the predicted covariance must match the scatter of points
    # intersected from clicks with 0.7 px noise (first-order propagation is exact to
    # well under 10 % at these angles); 4000 draws give the SDs to about 1.1 % (1 sd)
    rng = np.random.default_rng(7)
    half = baseline_m / 2
    centres = np.array([[-half, -half, 100.0], [half, -half, 100.0], [-half, half, 100.0], [half, half, 100.0]])
    intr, rv, t = _nadir_cameras(centres)
    X = np.array([3.0, -2.0, 1.0])
    clean = project(intr, rv, t, np.repeat(X[None], 4, 0))
    sigma = 0.7
    cov = triangulation_covariance(intr, rv, t, X, sigma)
    draws = 4000
    xy = np.repeat(clean[None], draws, 0) + rng.normal(0, sigma, (draws, 4, 2))
    pts, _ = triangulate(np.tile(intr, (draws, 1)), np.tile(rv, (draws, 1)), np.tile(t, (draws, 1)),
                         xy.reshape(-1, 2), np.repeat(np.arange(draws), 4), draws)
    empirical = np.std(pts - X, axis=0)
    assert np.sqrt(np.diag(cov)) == pytest.approx(empirical, rel=0.06)
    assert np.sqrt(np.diag(cov))[2] > np.sqrt(np.diag(cov))[0]  # height is the weak axis


def test_short_baseline_is_weak_in_height():
    # height precision ~ H / B: a 4 x shorter baseline is about 4 x weaker in height, while
    # the plan position (set by the pixel footprint) barely changes
    sd = {}
    for b in (10.0, 40.0):
        h = b / 2
        intr, rv, t = _nadir_cameras(np.array([[-h, -h, 100.0], [h, -h, 100.0], [-h, h, 100.0], [h, h, 100.0]]))
        sd[b] = np.sqrt(np.diag(triangulation_covariance(intr, rv, t, np.array([3.0, -2.0, 1.0]), 0.7)))
    assert sd[10.0][2] / sd[40.0][2] == pytest.approx(4.0, rel=0.1)
    assert sd[10.0][:2] == pytest.approx(sd[40.0][:2], rel=0.1)


def test_triangulation_covariance_needs_two_rays():
    intr, rv, t = _nadir_cameras(np.array([[0.0, 0.0, 100.0]]))
    assert np.all(np.isnan(triangulation_covariance(intr, rv, t, np.zeros(3), 0.7)))


def test_params_name_the_bad_key():
    with pytest.raises(InputError, match=r"georef.tape_file: the tape_horn method needs a file of taped distances"):
        GeorefParams.from_config({**PARAMS, "method": "tape_horn"})
    with pytest.raises(InputError, match=r"georef.qa: missing key 'max_residual_m'"):
        GeorefParams.from_config({**PARAMS, "qa": {k: v for k, v in PARAMS["qa"].items() if k != "max_residual_m"}})
    with pytest.raises(InputError, match=r"georef.bundle.refine_intrinsics: must be one of"):
        GeorefParams.from_config({**PARAMS, "bundle": {**PARAMS["bundle"], "refine_intrinsics": ["f", "k3"]}})
    p = GeorefParams.from_config(PARAMS)
    assert p.bundle.refine == ("f", "k1", "k2") and p.bundle.sigma_gcp_xy_m == 0.01 and p.qa.min_gcps_trusted == 4

def test_untrusted_verdict_names_the_gcp_and_says_the_file_disagrees_with_the_photos():
    model, gcps, infos, rows = _setup(displace_survey=(4, np.array([1.5, -1.0, 0.5])))
    r = georeference(model, gcps, infos, rows, {**PARAMS, "method": "similarity"}, "stored")
    rep = r.report
    assert rep["diagnosis"] == "inconsistent_with_photos"
    t4 = [f for f in rep["flagged_gcps"] if f["gcp_id"] == "T4"]
    assert t4 and "outlier" in t4[0]["flags"] and t4[0]["misfit_3d_m"] > 1.0
    assert any(s.startswith("GCP T4 flagged (") and "from the fit of the others" in s for s in rep["trust_reasons"])
    assert "T4" in rep["diagnosis_text"]


def test_metre_grade_coordinates_are_told_apart_from_a_bad_file():
    # every survey coordinate off by ~0.3 m at random, declared as 0.3 m: the file agrees with the
    # photos within what it claims, but that misses the 2 GSD requirement
    model, gcps, infos, rows = _setup()
    rng = np.random.default_rng(5)
    for g in gcps:
        g.xyz = g.xyz + rng.normal(0.0, 0.3, 3)
    params = {**PARAMS, "sigma_gcp_xy_m": 0.3, "sigma_gcp_z_m": 0.3,
              "qa": {**PARAMS["qa"], "max_residual_m": 2.0}}
    r = georeference(model, gcps, infos, rows, params, "stored")
    rep = r.report
    assert not rep["trusted"]
    assert rep["diagnosis"] == "coordinates_metre_grade", rep
    assert "metre-grade" in rep["diagnosis_text"]
    assert rep["diagnosis"] != "inconsistent_with_photos"
    r = georeference(*_setup()[:4], PARAMS, "stored")
    assert r.report["diagnosis"] == "trusted" and r.report["flagged_gcps"] == []


def _hilly(xy):
    """Ground with relief that no plane explains (the feet check needs it)."""
    return 100.0 + 0.05 * xy[:, 0] - 0.03 * xy[:, 1] + 4.0 * np.sin(xy[:, 0] / 25.0) * np.cos(xy[:, 1] / 30.0)


def test_placeholder_heights_give_a_plan_only_block_that_says_so():
    model, gcps, infos, rows = _setup()
    true_z = np.array([g.xyz[2] for g in gcps])
    for g in gcps:
        g.xyz[2] = 0.0
    r = georeference(model, gcps, infos, rows, PARAMS, "stored")
    res = r.residuals
    assert r.report["plan_only"] and r.report["height_datum"] == "relative"
    assert r.report["method"] == "similarity" and not r.report["trusted"] and r.report["diagnosis"] == "plan_only"
    assert "placeholders" in r.report["trust_reasons"][0] and "plan only" in r.report["diagnosis_text"]
    assert np.sqrt(np.mean(res["dx_m"] ** 2 + res["dy_m"] ** 2)) <= 2 * GSD  # plan position still from the GCPs
    assert np.isnan(r.report["gcp_rmse_z_m"])
    # heights are relative: up to a constant, the block's GCP heights follow the terrain to the levelling error
    from kitegully.georef.observations import triangulate_gcps, collect_observations
    obs = collect_observations(gcps, infos, rows, "stored", "stored", 1.0, 0.05)
    X, _ = triangulate_gcps(r.block, obs)
    dz = X[:, 2] - (true_z - true_z.mean())
    assert np.nanstd(dz) < 0.5  # 120 m block, mean axis of 20 cameras tilted 0.03 rad each: ~0.4 deg


def test_heights_in_feet_are_refused_from_the_photos_alone(monkeypatch):
    import georef.test_bundle as tb
    monkeypatch.setattr(tb, "_ground", _hilly)
    from kitegully.georef.heights import height_ratio
    from kitegully.georef.observations import collect_observations, triangulate_gcps
    model, gcps, infos, rows = _setup()
    obs = collect_observations(gcps, infos, rows, "stored", "stored", 1.0, 0.05)
    X, _ = triangulate_gcps(model, obs)
    survey = np.array([g.xyz for g in gcps]) - [340000.0, 5500000.0, 0.0]
    k, se, n = height_ratio(model, obs, X, survey)  # metres: the block's own height differences
    assert n == 7 and abs(k - 1.0) < 0.05 and se < 0.05
    for g in gcps:
        g.xyz[2] = g.xyz[2] / 0.3048
    with pytest.raises(InputError, match=r"^GCP file: the GCP height differences are 3\.\d\d times those the photos show "
                                         r"\(fitted over 7 GCPs\), as if the heights were in feet; set inputs.z_units: ft"):
        georeference(model, gcps, infos, rows, PARAMS, "stored")


def test_level_rotation_and_plan_similarity():
    from kitegully.georef.similarity import Similarity, level_rotation, plan_similarity
    d = np.array([0.1, -0.2, -0.9])
    assert np.allclose(level_rotation(d) @ (d / np.linalg.norm(d)), [0, 0, -1])
    assert np.allclose(level_rotation(np.array([0, 0, 1.0])) @ [0, 0, 1.0], [0, 0, -1])
    rng = np.random.default_rng(0)
    R = rotvec_to_matrix(np.array([[0.2, -0.1, 1.3]]))[0]
    truth = Similarity(3.0, R, np.array([5.0, -2.0, 40.0]))
    a = rng.normal(size=(6, 3)) * [30, 30, 3]
    b = truth.apply(a)
    s = plan_similarity(a, b[:, :2], R.T @ [0, 0, -1.0], z0=7.0)
    assert np.isclose(s.scale, 3.0) and np.allclose(s.apply(a)[:, :2], b[:, :2])
    assert np.allclose(s.apply(a)[:, 2] - np.median(s.apply(a)[:, 2]), b[:, 2] - np.median(b[:, 2]))
    with pytest.raises(InputError, match="share one plan position"):
        plan_similarity(a[:2], np.zeros((2, 2)), [0, 0, -1.0])
