"""Bad-input catalogue: each case breaks one thing of the valid site (site_factory) and names the expected line.

A case is ``(id, mutate, settings_overrides)``; ``mutate(site)`` edits the files in place.
"""

from __future__ import annotations

import shutil

from site_factory import CHECKPOINTS, GCP_XYZ, LAT, LON, gcp_lines, write_dem, write_heads, write_photo


def _gcp(site, text):
    site["gcp"].write_text(text, encoding="utf-8")


def _rows(fn):
    """GCP rows of the valid file, each passed through fn(i, j, row) -> row (None drops it)."""
    out = []
    for i, (x, y, z) in enumerate(GCP_XYZ):
        for j in (0, 1):
            r = fn(i, j, [x, y, z, 10 + 8 * i, 12 + 5 * i, f"img_{j}.jpg", f"g{i}"])
            if r is not None:
                out.append(r)
    return out


def _cps(site, text):
    site["checkpoints"].write_text(text, encoding="utf-8")


def _cp_rows(fn):
    return "id,x,y,z\n" + "".join(",".join(str(v) for v in fn(list(r))) + "\n" for r in CHECKPOINTS)


def _truncate(site):
    write_photo(site["images"] / "img_3.jpg", 3)
    p = site["images"] / "img_2.jpg"
    p.write_bytes(p.read_bytes()[: 600])


def _all_photos(site, **kw):
    for k in range(3):
        write_photo(site["images"] / f"img_{k}.jpg", k, **kw)


PHOTOS = [
    ("photos_folder_missing", lambda s: shutil.rmtree(s["images"]), {}),
    ("photos_folder_empty", lambda s: [p.unlink() for p in s["images"].iterdir()], {}),
    ("photo_not_an_image", lambda s: (write_photo(s["images"] / "img_3.jpg", 3),
                                      (s["images"] / "img_2.jpg").write_text("not a photo")), {}),
    ("photo_truncated", _truncate, {}),
    ("photo_duplicate_content", lambda s: shutil.copy(s["images"] / "img_0.jpg", s["images"] / "img_9.jpg"), {}),
    ("photos_fewer_than_three", lambda s: (s["images"] / "img_2.jpg").unlink(), {}),
    ("photos_mixed_camera_models", lambda s: write_photo(s["images"] / "img_2.jpg", 2, model=b"Canon EOS 5D"), {}),
    ("photos_mixed_pixel_sizes", lambda s: write_photo(s["images"] / "img_2.jpg", 2, size=(80, 60)), {}),
]

GCPS = [
    ("gcp_file_missing", lambda s: s["gcp"].unlink(), {}),
    ("gcp_file_empty", lambda s: _gcp(s, "\n# nothing\n"), {}),
    ("gcp_unknown_projection", lambda s: _gcp(s, gcp_lines(header="EPSG:99999")), {}),
    ("gcp_header_only", lambda s: _gcp(s, "EPSG:32632\n"), {}),
    ("gcp_short_row", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:5] if (i, j) == (0, 1) else r))), {}),
    ("gcp_non_numeric", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: [r[0], "4083900,5"] + r[2:] if (i, j) == (0, 1) else r))), {}),
    ("gcp_negative_pixel", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:3] + [-4] + r[4:] if (i, j) == (1, 0) else r))), {}),
    ("gcp_degrees_under_projected_header",
     lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: [LON + i * 1e-4, LAT + i * 1e-4] + r[2:]))), {}),
    ("gcp_one_row_in_degrees", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: [LON, LAT] + r[2:] if i == 2 else r))), {}),
    ("gcp_easting_northing_swapped", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: [r[1], r[0]] + r[2:]))), {}),
    ("gcp_outside_area_of_use", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: [r[0], r[1] + 5_400_000] + r[2:]))), {}),
    ("gcp_far_from_photo_gps", lambda s: _all_photos(s, gps=(LON + 2.0, LAT + 1.0, 400.0)), {}),
    ("gcp_one_point_far_from_the_others",
     lambda s: (_all_photos(s, gps=None), _gcp(s, gcp_lines(_rows(lambda i, j, r: [r[0] + 20000] + r[1:] if i == 3 else r)))), {}),
    ("gcp_heights_in_feet", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:2] + [round(r[2] / 0.3048, 2)] + r[3:]))), {}),
    ("gcp_heights_impossible", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:2] + [r[2] * 40] + r[3:]))), {}),
    ("gcp_duplicate_rows", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r) + _rows(lambda i, j, r: r if (i, j) == (1, 1) else None))), {}),
    ("gcp_fewer_than_three", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r if i < 2 else None))), {}),
    ("gcp_image_name_case_near_miss",
     lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:5] + ["IMG_1.JPG"] + r[6:] if j == 1 else r))), {}),
    ("gcp_no_image_in_folder", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:5] + [f"dsc_{j}.jpg"] + r[6:]))), {}),
    ("gcp_pixels_at_full_scale_declared_half", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:3] + [r[3] + 30, r[4]] + r[5:]))),
     {"gcp_pixel_scale": 0.5}),
    ("gcp_pixels_beyond_every_scale", lambda s: _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:3] + [r[3] * 100, r[4]] + r[5:]))), {}),
    ("gcp_pixels_in_the_rotated_frame",
     lambda s: (_all_photos(s, orientation=6), _gcp(s, gcp_lines(_rows(lambda i, j, r: r[:3] + [r[4], r[3] + 30] + r[5:])))), {}),
    ("gcp_csv_missing_column", lambda s: _gcp(s, "gcp_id,x,y,z,image,px\ng0,1,2,3,img_0.jpg,4\n"), {"gcp_format": "csv"}),
    ("gcp_csv_non_numeric", lambda s: _gcp(s, "gcp_id,x,y,z,image,px,py\n" + "".join(
        f"g{i},{x},{y},{'n/a' if i == 1 else z},img_{j}.jpg,10,12\n" for i, (x, y, z) in enumerate(GCP_XYZ) for j in (0, 1))),
     {"gcp_format": "csv"}),
]

CHECKPOINT_CASES = [
    ("checkpoints_missing", lambda s: s["checkpoints"].unlink(), {}),
    ("checkpoints_missing_column", lambda s: _cps(s, "id,x,y\nc1,1,2\n"), {}),
    ("checkpoints_non_numeric", lambda s: _cps(s, _cp_rows(lambda r: r[:3] + ["-"] if r[0] == "c2" else r)), {}),
    ("checkpoints_in_degrees", lambda s: _cps(s, _cp_rows(lambda r: [r[0], LON, LAT + 0.001 * int(r[0][1]), r[3]])), {}),
    ("checkpoints_swapped", lambda s: _cps(s, _cp_rows(lambda r: [r[0], r[2], r[1], r[3]])), {}),
    ("checkpoints_duplicate_id", lambda s: _cps(s, _cp_rows(lambda r: ["c1"] + r[1:] if r[0] == "c3" else r)), {}),
    ("checkpoints_heights_placeholder", lambda s: _cps(s, _cp_rows(lambda r: r[:3] + [0.0])), {}),
    ("checkpoints_heights_in_feet", lambda s: _cps(s, _cp_rows(lambda r: r[:3] + [round(r[3] / 0.3048, 2)])), {}),
]

RASTERS = [
    ("raster_missing", lambda s: s["dem"].unlink(), {}),
    ("raster_not_a_raster", lambda s: s["dem"].write_text("hello"), {}),
    ("raster_without_crs", lambda s: write_dem(s["dem"], crs=None), {}),
    ("raster_other_crs", lambda s: write_dem(s["dem"], crs="EPSG:32633"), {}),
    ("raster_cells_not_square", lambda s: write_dem(s["dem"], res=(1.0, 0.5)), {}),
    ("raster_undeclared_9999", lambda s: write_dem(s["dem"], fill=-9999.0), {}),
    ("raster_undeclared_32768", lambda s: write_dem(s["dem"], fill=-32768.0), {}),
    ("raster_undeclared_float_max", lambda s: write_dem(s["dem"], fill=3.4028235e38), {}),
]

VECTORS = [
    ("heads_missing", lambda s: s["heads"].unlink(), {}),
    ("heads_not_a_vector_file", lambda s: s["heads"].write_text("x"), {}),
    ("heads_without_crs", lambda s: write_heads(s["heads"], crs=None), {}),
    ("heads_other_crs", lambda s: write_heads(s["heads"], crs="EPSG:4326"), {}),
    ("heads_empty", lambda s: write_heads(s["heads"], n=0), {}),
]

CASES = PHOTOS + GCPS + CHECKPOINT_CASES + RASTERS + VECTORS
