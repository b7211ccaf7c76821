"""Bad-input catalogue (issue 14): every case breaks one input of a valid tiny site and must be refused
with exactly one line naming the file and the problem, before any product is written.

The site is built by site_factory (3 JPEGs with EXIF GPS, an ODM GCP file in EPSG:32632,
checkpoints, a DEM); the cases are in cases.py. ``{root}`` stands for the site's folder.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).parent))

from cases import CASES  # noqa: E402
from site_factory import GCP_XYZ, gcp_lines, make_site, write_dem  # noqa: E402

from kitegully import InputError  # noqa: E402
from kitegully.config import load_yaml, validate_config  # noqa: E402
from kitegully.inputs import InputSettings, check_inputs  # noqa: E402

REPO = Path(__file__).resolve().parents[2]

EXPECTED = {
    'photos_folder_missing': '{root}/images: image folder not found',
    'photos_folder_empty': '{root}/images: no JPEG/TIFF/PNG images in the folder',
    'photo_not_an_image': '{root}/images: unreadable or truncated image(s): img_2.jpg (not an image file)',
    'photo_truncated': '{root}/images: unreadable or truncated image(s): img_2.jpg (truncated)',
    'photo_duplicate_content': '{root}/images: the same photograph under two names: img_9.jpg = img_0.jpg; remove the copies',
    'photos_fewer_than_three': '{root}/images: only 2 readable photograph(s); structure from motion needs at least 3',
    'photos_mixed_camera_models': "{root}/images: photographs from 2 cameras (Canon PowerShot A3300 IS 64x48 px: 2; Canon EOS 5D 64x48 px: 1); each camera is calibrated on its own, so each needs at least 3 photos: remove the odd ones or add more",
    'photos_mixed_pixel_sizes': "{root}/images: photographs from 2 cameras (Canon PowerShot A3300 IS 64x48 px: 2; Canon PowerShot A3300 IS 80x60 px: 1); each camera is calibrated on its own, so each needs at least 3 photos: remove the odd ones or add more",
    'gcp_file_missing': '{root}/gcp_list.txt: GCP file not found',
    'gcp_file_empty': '{root}/gcp_list.txt: GCP file is empty',
    'gcp_unknown_projection': "{root}/gcp_list.txt: line 1: projection 'EPSG:99999' is not understood (Invalid projection: EPSG:99999: (Internal Proj Error: proj_create: crs not found: EPSG:99999))",
    'gcp_header_only': '{root}/gcp_list.txt: GCP file has a projection line but no observations',
    'gcp_short_row': "{root}/gcp_list.txt: line 3: expected 'geo_x geo_y geo_z im_x im_y image_name [gcp_name]', got '544500.0 4083900.0 300.0 10 12'",
    'gcp_non_numeric': "{root}/gcp_list.txt: line 3: non-numeric coordinate in '544500.0 4083900,5 300.0 10 12 img_1.jpg g0'",
    'gcp_negative_pixel': "{root}/gcp_list.txt: line 4: invalid (non-finite or negative) value in '544540.0 4083910.0 301.5 -4 17 img_0.jpg g1'",
    'gcp_degrees_under_projected_header': '{root}/gcp_list.txt: GCP coordinates look like degrees (x 9.5 to 9.5003, y 36.9 to 36.9) but EPSG:32632 is in metres; give projected coordinates or declare the geographic CRS',
    'gcp_one_row_in_degrees': '{root}/gcp_list.txt: line 6: x 9.5, y 36.9 look like degrees but EPSG:32632 is in metres; give projected coordinates',
    'gcp_easting_northing_swapped': '{root}/gcp_list.txt: easting and northing look swapped: line 2 has x 4083900.000, y 544500.000, which lies outside EPSG:32632 (Between 6°E and 12°E, northern hemisphere between equator and 84°N, onshore and offshore), but swapped every GCP falls inside it',
    'gcp_outside_area_of_use': '{root}/gcp_list.txt: 8 GCP(s) lie outside the area of use of EPSG:32632 (Between 6°E and 12°E, northern hemisphere between equator and 84°N, onshore and offshore), first on line 2 (x 544500.000, y 9483900.000); check the CRS and the coordinates',
    'gcp_far_from_photo_gps': "{root}/gcp_list.txt: GCP on line 2 is 209 km from the nearest photograph's EXIF GPS position (the points must lie in the photos); check the CRS (EPSG:32632) and the coordinates (1 more problem(s) listed in the log)",
    'gcp_one_point_far_from_the_others': '{root}/gcp_list.txt: line 8: GCP lies 20.0 km from the middle of the others; a photo block is far smaller, so check its coordinates',
    'gcp_heights_in_feet': "{root}/gcp_list.txt: GCP heights (median 990.0 m) lie above the cameras' EXIF GPS altitude (median 400.0 m); in feet they would be 302 m, below the cameras; set inputs.z_units: ft (or us_ft) so they are converted",
    'gcp_heights_impossible': '{root}/gcp_list.txt: GCP heights up to 12120.0 cannot be metres; if they are feet, set inputs.z_units: ft (or us_ft) so they are converted',
    'gcp_duplicate_rows': '{root}/gcp_list.txt: duplicate row(s): line 10 repeats line 5; remove the repeats',
    'gcp_fewer_than_three': '{root}/gcp_list.txt: only 2 GCP(s); georeferencing needs at least 3',
    'gcp_image_name_case_near_miss': "{root}/gcp_list.txt: line 3: image 'IMG_1.JPG' is not in the photo folder, but 'img_1.jpg' is (the names differ only in upper/lower case); write the names exactly as the files are named (4 rows affected)",
    'gcp_no_image_in_folder': "{root}/gcp_list.txt: none of the images the file names is in the photo folder (e.g. 'dsc_0.jpg' on line 2)",
    'gcp_pixels_at_full_scale_declared_half': '{root}/gcp_list.txt: line 8: pixel (64, 27) on img_0.jpg lies outside its 32 x 24 px at georef.gcp_pixel_scale 0.5 (8 point(s) outside); they fit inside the images at gcp_pixel_scale 1 (full resolution) (the smallest scale that holds them all is 1.0000)',
    'gcp_pixels_beyond_every_scale': '{root}/gcp_list.txt: line 8: pixel (3400, 27) on img_0.jpg lies outside its 64 x 48 px at georef.gcp_pixel_scale 1 (8 point(s) outside); they fit at no usual scale (the smallest scale that holds them all is 53.1250)',
    'gcp_pixels_in_the_rotated_frame': '{root}/gcp_list.txt: line 8: pixel (27, 64) on img_0.jpg lies outside its 64 x 48 px at georef.gcp_pixel_scale 1 (4 point(s) outside); they fit in the display (EXIF-rotated) frame at the declared scale; set georef.gcp_pixel_frame: display',
    'gcp_csv_missing_column': '{root}/gcp_list.txt: missing column(s) py; expected gcp_id, x, y, z, image, px, py',
    'gcp_csv_non_numeric': '{root}/gcp_list.txt: line 4: missing or non-numeric value',
    'checkpoints_missing': '{root}/checkpoints.csv: checkpoint file not found',
    'checkpoints_missing_column': '{root}/checkpoints.csv: missing column(s) z; expected id, x, y, z (coordinates in the site CRS, m)',
    'checkpoints_non_numeric': '{root}/checkpoints.csv: line 3: missing or non-numeric coordinate',
    'checkpoints_in_degrees': '{root}/checkpoints.csv: checkpoint coordinates look like degrees (x 9.5 to 9.5, y 36.901 to 36.903) but EPSG:32632 is in metres; give projected coordinates or declare the geographic CRS',
    'checkpoints_swapped': '{root}/checkpoints.csv: easting and northing look swapped: line 2 has x 4083930.000, y 544530.000, which lies outside EPSG:32632 (Between 6°E and 12°E, northern hemisphere between equator and 84°N, onshore and offshore), but swapped every checkpoint falls inside it',
    'checkpoints_duplicate_id': "{root}/checkpoints.csv: duplicate checkpoint id 'c1' on lines 2 and 4",
    'checkpoints_heights_placeholder': '{root}/checkpoints.csv: all 3 checkpoint heights are 0, which looks like a placeholder, not surveyed heights; checkpoints validate heights, so give surveyed heights or leave the checkpoint file out',
    'checkpoints_heights_in_feet': "{root}/checkpoints.csv: checkpoint heights (median 987.5 m) lie above the cameras' EXIF GPS altitude (median 400.0 m); in feet they would be 301 m, below the cameras; set inputs.z_units: ft (or us_ft) so they are converted",
    'raster_missing': '{root}/dem.tif: raster named in inputs.rasters not found',
    'raster_not_a_raster': "{root}/dem.tif: not a readable raster ('{root}/dem.tif' not recognized as being in a supported file format.)",
    'raster_without_crs': '{root}/dem.tif: the raster has no CRS; it must be in the site CRS EPSG:32632',
    'raster_other_crs': '{root}/dem.tif: the raster is in EPSG:32633, not the site CRS EPSG:32632; reproject it first',
    'raster_cells_not_square': '{root}/dem.tif: cells are not square (1 x 0.5 m); resample to square cells',
    'raster_undeclared_9999': '{root}/dem.tif: 9 cells hold -9999 but the raster declares no such nodata value; declare it (nodata in the file or inputs.rasters[].nodata) so it is not read as elevation',
    'raster_undeclared_32768': '{root}/dem.tif: 9 cells hold -32768 but the raster declares no such nodata value; declare it (nodata in the file or inputs.rasters[].nodata) so it is not read as elevation',
    'raster_undeclared_float_max': '{root}/dem.tif: 9 cells hold 3.4e38 (float32 maximum) but the raster declares no such nodata value; declare it (nodata in the file or inputs.rasters[].nodata) so it is not read as elevation',
    'heads_missing': '{root}/heads.gpkg: file named in gully.heads_file not found',
    'heads_not_a_vector_file': "{root}/heads.gpkg: not a readable vector file ('{root}/heads.gpkg' not recognized as being in a supported file format.)",
    'heads_without_crs': '{root}/heads.gpkg: the layer has no CRS; it must be in the site CRS EPSG:32632',
    'heads_other_crs': '{root}/heads.gpkg: the layer is in EPSG:4326, not the site CRS EPSG:32632; reproject it first',
    'heads_empty': '{root}/heads.gpkg: the layer named in gully.heads_file has no features',
}


def _run(site: dict, **over):
    settings = InputSettings(**{"crs": "EPSG:32632", "gcp_format": "odm", "rasters": ((str(site["dem"]), None),),
                           "vectors": ((str(site["heads"]), "gully.heads_file"),), **over})
    out = {k: site["out"] / v for k, v in dict(report="report.md", json="report.json", gcp="gcp.txt", checkpoints="cp.csv").items()}
    return check_inputs(settings, site["images"], site["gcp"], site["checkpoints"], out, "t"), out


def test_the_catalogue_has_at_least_40_cases():
    assert len(CASES) >= 40 and {c[0] for c in CASES} == set(EXPECTED)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_refused_with_one_line(case, tmp_path):
    cid, mutate, over = case
    site = make_site(tmp_path / "site")
    mutate(site)
    with pytest.raises(InputError) as err:
        _run(site, **over)
    msg = str(err.value)
    assert msg == EXPECTED[cid].replace("{root}", str(site["root"]))
    assert "\n" not in msg
    out = site["out"]
    assert not (out / "gcp.txt").exists() and not (out / "cp.csv").exists()  # no product
    rep = json.loads((out / "report.json").read_text())
    assert rep["verdict"] == "refused" and msg.startswith(rep["errors"][0]["line"])


def test_valid_site_is_accepted_and_copies_written(tmp_path):
    site = make_site(tmp_path / "site")
    found, out = _run(site)
    assert found.ok and found.facts["n_photos"] == 3 and found.facts["n_gcps"] == 4
    assert out["gcp"].read_text() == site["gcp"].read_text()
    assert json.loads(out["json"].read_text())["verdict"] == "accepted"
    assert "Verdict: accepted" in out["report"].read_text()


def test_placeholder_gcp_heights_are_accepted_for_plan_only_georeferencing(tmp_path):
    from cases import _rows
    site = make_site(tmp_path / "site")
    site["gcp"].write_text(gcp_lines(_rows(lambda i, j, r: r[:2] + [0.0] + r[3:])))
    found, out = _run(site)
    assert found.ok and found.facts["plan_only"]
    warn = [f.line for f in found.of("warning")]
    assert f"{site['gcp']}: all 8 GCP heights are 0, which looks like a placeholder, not surveyed heights; the block will be " \
           "georeferenced in plan only and its heights will be relative" in warn
    assert "plan only" in out["report"].read_text()


def test_heights_in_feet_are_converted_when_declared(tmp_path):
    site = make_site(tmp_path / "site")
    rows = [(x, y, round(z / 0.3048, 3), 10 + 8 * i, 12 + 5 * i, f"img_{j}.jpg", f"g{i}") for i, (x, y, z) in enumerate(GCP_XYZ) for j in (0, 1)]
    site["gcp"].write_text(gcp_lines(rows))
    cps = pd.read_csv(site["checkpoints"])
    cps["z"] = cps["z"] / 0.3048
    cps.to_csv(site["checkpoints"], index=False)
    found, out = _run(site, z_units="ft")
    assert found.ok
    z = [float(ln.split()[2]) for ln in out["gcp"].read_text().splitlines()[1:]]
    assert np.allclose(z, [r[2] for r in GCP_XYZ for _ in (0, 1)], atol=1e-3)
    assert np.allclose(pd.read_csv(out["checkpoints"])["z"], pd.read_csv(tmp_path / "site" / "checkpoints.csv")["z"] * 0.3048)


def test_two_cameras_with_three_photos_each_are_accepted_with_a_warning(tmp_path):
    from site_factory import write_photo

    site = make_site(tmp_path / "site")
    for k in range(3, 6):
        write_photo(site["images"] / f"img_{k}.jpg", k, model=b"Canon EOS 5D")
    found, _ = _run(site)
    assert found.ok and len(found.facts["cameras"]) == 2
    assert [f.message for f in found.of("warning")] == [
        "photographs from 2 cameras (Canon PowerShot A3300 IS 64x48 px: 3; Canon EOS 5D 64x48 px: 3); SfM calibrates one camera group each"]


def test_declared_nodata_sentinel_is_accepted(tmp_path):
    site = make_site(tmp_path / "site")
    write_dem(site["dem"], fill=-9999.0)
    found, _ = _run(site, rasters=((str(site["dem"]), -9999.0),))
    assert found.ok
    write_dem(site["dem"], fill=-9999.0, nodata=-9999.0)
    assert _run(site)[0].ok


@pytest.mark.realdata
def test_boruszyn_real_data_passes(boruszyn_dir, tmp_path):
    s = InputSettings(crs="EPSG:2180", gcp_format="odm", gcp_pixel_scale=0.5208333333333334)
    out = {k: tmp_path / v for k, v in dict(report="r.md", json="r.json", gcp="g.txt").items()}
    found = check_inputs(s, boruszyn_dir / "images", boruszyn_dir / "gcp_list.txt", None, out, "boruszyn_kap")
    assert found.ok and found.facts["n_photos"] == 28 and found.facts["n_gcps"] == 6


# --- configurations: refused when the Snakefile validates them, before any job ---

def _site_file(tmp_path, edit, text=None):
    cfg = load_yaml(REPO / "config" / "sites" / "boruszyn_kap.yaml")
    edit(cfg)
    path = tmp_path / "site.yaml"
    path.write_text(text if text is not None else yaml.safe_dump(cfg), encoding="utf-8")
    return path


def _validate(path):
    merged = load_yaml(REPO / "config" / "config.yaml") | load_yaml(path)
    validate_config(merged, sources=[path])


CONFIG_CASES = [
    ("config_crs_geographic", lambda c: c["site"].update(crs="EPSG:4326"),
     "{f}: site.crs: 'EPSG:4326' is geographic (degrees); give a projected CRS in metres such as the site's UTM zone (EPSG:326xx north, EPSG:327xx south)"),
    ("config_crs_unknown", lambda c: c["site"].update(crs="EPSG:99999"),
     "{f}: site.crs: 'EPSG:99999' is not a known CRS; give a projected CRS in metres such as EPSG:32632 (UTM 32N)"),
    ("config_crs_in_feet", lambda c: c["site"].update(crs="EPSG:2227"),
     "{f}: site.crs: 'EPSG:2227' has units of US survey foot; kitegully needs a projected CRS in metres"),
    ("config_z_units_unknown", lambda c: c["inputs"].update(z_units="yards"),
     "{f}: inputs.z_units: 'yards' is not one of ['m', 'ft', 'us_ft']"),
    ("config_raster_without_path", lambda c: c["inputs"].update(rasters=[{"nodata": -9999}]),
     "{f}: inputs.rasters.0: 'path' is a required property"),
]


@pytest.mark.parametrize("case", CONFIG_CASES, ids=[c[0] for c in CONFIG_CASES])
def test_bad_config_is_refused_with_one_line(case, tmp_path):
    _, edit, expected = case
    path = _site_file(tmp_path, edit)
    with pytest.raises(InputError) as err:
        _validate(path)
    assert str(err.value) == expected.format(f=path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site.yaml"]  # nothing else written


def test_yaml_syntax_error_names_file_and_line(tmp_path):
    path = tmp_path / "site.yaml"
    path.write_text("site:\n  name: x\n  kind: [real\nseed: 1\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        _validate(path)
    assert str(err.value) == f"{path}: not valid YAML (line 4): expected ',' or ']', but got ':'"


def test_config_command_line_check_prints_one_line(tmp_path):
    import subprocess

    path = _site_file(tmp_path, lambda c: c["site"].update(crs="EPSG:4326"))
    proc = subprocess.run([sys.executable, "-m", "kitegully.config", str(path)], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 1 and proc.stderr.strip().splitlines() == [
        f"Invalid configuration: {path}: site.crs: 'EPSG:4326' is geographic (degrees); give a projected CRS in metres "
        "such as the site's UTM zone (EPSG:326xx north, EPSG:327xx south)"]
