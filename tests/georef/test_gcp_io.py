"""GCP file parsing: each projection form, names, CSV, bad rows, reprojection."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import Transformer

from kitegully import InputError
from kitegully.georef.gcp_io import parse_projection, read_gcps, read_tape_distances

ROWS = """340607.768 548220.879 70.8 149 1620 a.jpg
340607.768 548220.879 70.8 1607 1061 b.jpg
340644.813 548180.885 70 239 1134 a.jpg
"""


def _write(tmp_path, text, name="gcp_list.txt"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_epsg_line_groups_by_coordinates_and_names_in_order(tmp_path):
    gcps = read_gcps(_write(tmp_path, "EPSG:2180\n" + ROWS), "EPSG:2180")
    assert [g.gcp_id for g in gcps] == ["GCP1", "GCP2"]
    assert gcps[0].images == ["a.jpg", "b.jpg"]
    np.testing.assert_allclose(gcps[0].pixels, [[149, 1620], [1607, 1061]])
    assert len(gcps[1].images) == 1  # a GCP seen once is kept; QA flags it single_obs
    np.testing.assert_allclose(gcps[1].xyz, [340644.813, 548180.885, 70.0])


def test_name_column_and_comments(tmp_path):
    text = "# a comment\nEPSG:32632\n500000 4000000 10 1 2 x.jpg T1\n500001 4000000 10 3 4 y.jpg T1 extra\n"
    gcps = read_gcps(_write(tmp_path, text), "EPSG:32632")
    assert len(gcps) == 1 and gcps[0].gcp_id == "T1"
    # two rows of one named GCP disagree by 1 m: median position and the spread are reported
    assert gcps[0].coord_spread_m == pytest.approx(1.0)


@pytest.mark.parametrize("line", ["WGS84 UTM 32N", "+proj=utm +zone=32 +datum=WGS84 +units=m +no_defs", "EPSG:32632"])
def test_projection_forms_reproject_identically(tmp_path, line):
    text = f"{line}\n500000 4000000 100 10 20 a.jpg G\n"
    g = read_gcps(_write(tmp_path, text), "EPSG:32633")[0]
    x, y = Transformer.from_crs("EPSG:32632", "EPSG:32633", always_xy=True).transform(500000, 4000000)
    np.testing.assert_allclose(g.xyz[:2], [x, y], atol=1e-6)
    assert g.xyz[2] == pytest.approx(100.0)


def test_utm_south_and_lonlat(tmp_path):
    assert parse_projection("WGS84 UTM 33S").to_epsg() == 32733
    g = read_gcps(_write(tmp_path, "EPSG:4326\n9.0 36.0 50 1 1 a.jpg G\n"), "EPSG:32632")[0]
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True).transform(9.0, 36.0)
    np.testing.assert_allclose(g.xyz[:2], [x, y], atol=1e-6)


@pytest.mark.parametrize(
    "text, message",
    [
        ("EPSG:2180\n1 2 3 4 a.jpg\n", "line 2"),
        ("EPSG:2180\n1 2 x 4 5 a.jpg\n", "line 2: non-numeric"),
        ("EPSG:2180\n1 2 3 -4 5 a.jpg\n", "line 2"),
        ("WGS84 UTM 99N\n1 2 3 4 5 a.jpg\n", "line 1: projection"),
        ("not a crs\n1 2 3 4 5 a.jpg\n", "line 1: projection"),
        ("EPSG:2180\n", "no observations"),
        ("", "empty"),
    ],
)
def test_bad_files_name_file_and_problem(tmp_path, text, message):
    p = _write(tmp_path, text)
    with pytest.raises(InputError, match=message) as err:
        read_gcps(p, "EPSG:2180")
    assert str(p) in str(err.value)


def test_csv_form_and_its_errors(tmp_path):
    p = _write(tmp_path, "gcp_id,x,y,z,image,px,py\nA,1,2,3,a.jpg,10,20\nA,1,2,3,b.jpg,11,21\nB,5,6,7,a.jpg,30,40\n", "g.csv")
    gcps = read_gcps(p, "EPSG:2180")
    assert [g.gcp_id for g in gcps] == ["A", "B"] and gcps[0].images == ["a.jpg", "b.jpg"]
    bad = _write(tmp_path, "gcp_id,x,y,z,image,px,py\nA,1,2,zz,a.jpg,10,20\n", "bad.csv")
    with pytest.raises(InputError, match="line 2"):
        read_gcps(bad, "EPSG:2180")
    with pytest.raises(InputError, match="missing column"):
        read_gcps(_write(tmp_path, "id,x\n1,2\n", "c.csv"), "EPSG:2180")


def test_tape_file(tmp_path):
    df = read_tape_distances(_write(tmp_path, "gcp_a,gcp_b,distance_m\nA,B,2.0\n", "t.csv"))
    assert df["distance_m"].tolist() == [2.0]
    with pytest.raises(InputError, match="positive"):
        read_tape_distances(_write(tmp_path, "gcp_a,gcp_b,distance_m\nA,B,-1\n", "t2.csv"))


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_gcps(tmp_path / "nope.txt", "EPSG:2180")
