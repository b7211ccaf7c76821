"""The sparse cloud is LAZ by default (laspy + lazrs) and the same points as the LAS option."""

from __future__ import annotations

from types import SimpleNamespace

import laspy
import numpy as np
import pytest

from kitegully.georef.export import write_las

OFFSET = np.array([578800.0, 4081500.0, 100.0])


class _Track:
    def __init__(self, n: int):
        self.n = n

    def length(self) -> int:
        return self.n


def _model(n: int = 500) -> SimpleNamespace:
    """What write_las reads of a pycolmap.Reconstruction: points3D with xyz, color, track."""
    rng = np.random.default_rng(11)
    xyz = rng.uniform([-100, -100, 0], [100, 100, 30], (n, 3))
    rgb = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    tl = rng.integers(2, 12, n)
    pts = {k + 1: SimpleNamespace(xyz=xyz[k], color=rgb[k], track=_Track(int(tl[k]))) for k in range(n)}
    return SimpleNamespace(points3D=pts)


def test_laz_opens_with_laspy_and_equals_the_las(tmp_path):
    rec = _model()
    n_laz = write_las(rec, OFFSET, "EPSG:32632", tmp_path / "cloud.laz")
    n_las = write_las(rec, OFFSET, "EPSG:32632", tmp_path / "cloud.las")
    assert n_laz == n_las == 500
    laz, las = laspy.read(tmp_path / "cloud.laz"), laspy.read(tmp_path / "cloud.las")
    assert laz.header.are_points_compressed and not las.header.are_points_compressed
    assert (tmp_path / "cloud.laz").stat().st_size < (tmp_path / "cloud.las").stat().st_size
    assert laz.header.point_format.id == las.header.point_format.id == 7
    for dim in ("X", "Y", "Z", "red", "green", "blue", "intensity"):
        np.testing.assert_array_equal(laz[dim], las[dim], err_msg=dim)
    assert laz.header.parse_crs().to_epsg() == 32632
    pts = np.array([p.xyz for p in rec.points3D.values()]) + OFFSET
    np.testing.assert_allclose(np.c_[laz.x, laz.y, laz.z], pts, atol=0.0005)  # 1 mm scale
    tracks = np.array([p.track.length() for p in rec.points3D.values()])
    np.testing.assert_array_equal(laz.intensity, tracks)


def test_other_suffix_is_refused(tmp_path):
    with pytest.raises(ValueError, match="end in .laz or .las"):
        write_las(_model(5), OFFSET, "EPSG:32632", tmp_path / "cloud.ply")
