"""Verified matches counted by sensor pair from a COLMAP database."""

from __future__ import annotations

import sqlite3

from kitegully.lowcost.matches import MAX_IMAGE_ID, matches_by_pair_type


def test_matches_are_counted_by_sensor_pair(tmp_path):
    db = tmp_path / "database.db"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE images (image_id INTEGER, name TEXT)")
    con.execute("CREATE TABLE two_view_geometries (pair_id INTEGER, rows INTEGER)")
    con.executemany("INSERT INTO images VALUES (?, ?)", [(1, "0000_rgb_000.jpg"), (2, "0001_rgb_001.jpg"), (3, "0002_nir_000.jpg")])
    pairs = [(1, 2, 800), (1, 3, 150), (2, 3, 10)]                        # the last one is below the minimum
    con.executemany("INSERT INTO two_view_geometries VALUES (?, ?)", [(a * MAX_IMAGE_ID + b, n) for a, b, n in pairs])
    con.commit()
    con.close()
    names = {"0000_rgb_000.jpg": "rgb_000.jpg", "0001_rgb_001.jpg": "rgb_001.jpg", "0002_nir_000.jpg": "nir_000.jpg"}
    t = matches_by_pair_type(db, names, 15).set_index("pair_type")
    assert t.loc["RGB-RGB", "pairs_matched"] == 1 and t.loc["RGB-RGB", "mean_matches_per_matched_pair"] == 800
    assert t.loc["RGB-NIR", "pairs_tested"] == 2 and t.loc["RGB-NIR", "pairs_matched"] == 1
    assert t.loc["NIR-NIR", "pairs_matched"] == 0
    assert t.loc["RGB-NIR", "paper_mean_matches"] == 188.2
