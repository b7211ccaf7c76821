"""Pole-camera walk around a close-range scene: geometry, folding rule, rendered spheres."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from kitegully import InputError
from kitegully.closerange.spheres import detect_spheres
from kitegully.seeds import rng_for
from kitegully.twin.closerange import generate_scene, scene_origin
from kitegully.twin.polewalk import PoleWalk, photograph_walk, prepare_pole_scene, project_spheres, walk_poses
from kitegully.twin.render import surface_height

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def pole_scene():
    cfg = yaml.safe_load((REPO / "config" / "sites" / "tiny_twin.yaml").read_text())
    p = cfg["obia"]["scenes"]
    sc = generate_scene("scene_01", p, p["list"][0], 1, "EPSG:32632", scene_origin(0, p))
    return sc, prepare_pole_scene(sc, 0.10, True, rng_for(1, "test", "rule"))


def test_walk_rings_the_patch_with_oblique_views(pole_scene):
    sc, ps = pole_scene
    walk = PoleWalk(n_images=24)
    poses = walk_poses(ps, walk, rng_for(1, "test", "walk"))
    C = np.array([p.C for p in poses])
    r = np.hypot(C[:, 0] - ps.patch_centre[0], C[:, 1] - ps.patch_centre[1])
    assert abs(np.median(r) - (ps.patch_reach_m + walk.standoff_m)) < 0.2
    ang = np.sort(np.arctan2(C[:, 1] - ps.patch_centre[1], C[:, 0] - ps.patch_centre[0]))
    assert np.diff(np.r_[ang, ang[0] + 2 * np.pi]).max() < np.radians(25)  # a closed ring
    cam = walk.camera()
    assert cam.f == pytest.approx(24.0 * 1200 / 36.0)
    target = np.r_[ps.patch_centre, surface_height(ps.render, ps.patch_centre[:1], ps.patch_centre[1:])]
    for pose in poses:
        axis = pose.R[2]
        assert -0.95 < axis[2] < -0.1  # looking down, not nadir: oblique
        uv = cam.project(target[None], pose)
        assert cam.in_image(uv, 20)[0]  # the patch is in view
        assert pose.C[2] - target[2] > 0.3  # the camera on its pole looks down onto the patch


def test_spheres_and_folding_rule_are_placed(pole_scene):
    sc, ps = pole_scene
    assert len(ps.spheres) == sc.meta["markers"] == 4
    # true centres agree with the surveyed ones within the survey noise (RTK, 1.5 cm SD)
    obs = sc.markers[["x", "y", "z"]].to_numpy()
    d = np.linalg.norm(ps.spheres[:, None] - obs[None], axis=2).min(axis=1)
    assert d.max() < 0.08
    a, corner, b = ps.rule
    assert np.linalg.norm(a - corner) == pytest.approx(1.0) and np.linalg.norm(b - corner) == pytest.approx(1.0)
    assert np.dot(a - corner, b - corner) == pytest.approx(0.0, abs=1e-9)  # orthogonal legs
    # the rigid rule rests on the ground: above the surface all along its legs, touching it
    s = np.linspace(0.0, 1.0, 201)[:, None]
    P = np.vstack([corner + s * (a - corner), corner + s * (b - corner)])
    gap = P[:, 2] - surface_height(ps.render, P[:, 0], P[:, 1])
    assert gap.min() > 0.0 and gap.min() < 0.01
    # laid beside the patch, inside the ring the photographer walks (not in the periphery)
    assert np.hypot(*(ps.rule[:, :2] - ps.patch_centre).T).max() < ps.patch_reach_m + PoleWalk().standoff_m
    assert prepare_pole_scene(sc, 0.10, False, rng_for(1, "t", "r")).rule is None


def test_rendered_walk_photos_give_sphere_centres_to_half_a_pixel(pole_scene):
    _, ps = pole_scene
    walk = PoleWalk(n_images=3, image_width_px=900, image_height_px=600)
    poses = walk_poses(ps, walk, rng_for(1, "test", "walk3"))
    cam = walk.camera()
    errors = []
    for i, img in photograph_walk(ps, walk, poses, rng_for(1, "test", "photo")):
        assert img.shape == (600, 900, 3) and img.dtype == np.uint8
        truth = project_spheres(cam, poses[i], ps.spheres)
        for u, v in detect_spheres(img, cam)[["u_px", "v_px"]].to_numpy():
            errors.append(np.hypot(truth[:, 0] - u, truth[:, 1] - v).min())
    assert len(errors) >= 3
    assert max(errors) < 0.5  # no false blob either: every detection is a sphere


def test_pole_walk_config_is_validated():
    assert PoleWalk.from_config({"n_images": 48}).n_images == 48
    with pytest.raises(InputError, match="unknown key"):
        PoleWalk.from_config({"n_photos": 48})
    with pytest.raises(InputError, match="at least 3"):
        PoleWalk.from_config({"n_images": 2})


def test_a_ring_wider_than_the_scene_follows_the_ground_edge_but_stays_off_the_patch(pole_scene):
    import dataclasses

    from kitegully.twin.polewalk import ground_reach

    _, ps = pole_scene
    walk = PoleWalk(n_images=36, radius_jitter_m=0.0)
    wide = dataclasses.replace(ps, patch_reach_m=ps.patch_reach_m + 10.0)  # spheres far out: nominal ring off the scene
    floor = ps.patch_reach_m + walk.standoff_m
    poses = walk_poses(wide, walk, rng_for(1, "test", "walk_ground"), min_radius_m=floor)
    C = np.array([p.C for p in poses])
    ang = np.arctan2(C[:, 1] - ps.patch_centre[1], C[:, 0] - ps.patch_centre[0])
    r = np.hypot(C[:, 0] - ps.patch_centre[0], C[:, 1] - ps.patch_centre[1])
    edge = ground_reach(ps.render, ps.patch_centre, ang)
    assert np.all(r <= np.maximum(edge, floor) + 1e-6)  # on the ground, or at the floor where the ground is nearer
    assert np.all(r >= floor - 1e-6)  # never on the patch
    assert np.isfinite(surface_height(ps.render, C[r < edge - 1e-6, 0], C[r < edge - 1e-6, 1])).all()


def test_rule_is_laid_as_close_to_the_patch_as_it_fits():
    """A 20 m flat scene with a 2 m-radius patch in its middle: the rule lands on the grass ring
    around the patch (within 1.5 m of its edge), not anywhere in the 20 m square."""
    from kitegully.io.raster import GridSpec
    from kitegully.twin.polewalk import _lay_rule

    g = GridSpec(0.0, 20.0, 0.05, 400, 400, "EPSG:32632")
    xs, ys = g.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    centre = np.array([10.0, 10.0])
    free = np.hypot(X - centre[0], Y - centre[1]) > 2.0
    dem = np.zeros((400, 400))
    ends = _lay_rule(g, free, dem, rng_for(4, "test", "rule_near"), centre)
    d = np.hypot(*(ends[:, :2] - centre).T)
    assert d.min() > 2.0 and d.max() <= 3.5
    assert ends[:, 2] == pytest.approx(0.003)  # the top of a 3 mm rule on flat ground


def test_rigid_rule_rests_on_the_highest_tussocks_not_draped():
    """Flat ground with three 10 cm tussocks under the rule: the rule rests on them (a plane
    10 cm up, touching all three) instead of following the ground as a painted strip did."""
    from kitegully.io.raster import GridSpec
    from kitegully.twin.polewalk import resting_plane

    g = GridSpec(0.0, 4.0, 0.02, 200, 200, "EPSG:32632")
    xs, ys = g.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    dem = 0.02 * np.sin(7 * X) * np.cos(5 * Y)  # grass relief, +-2 cm
    corner = np.array([1.0, 1.0])
    for p in ([1.0, 1.0], [2.0, 1.0], [1.0, 2.0]):  # under the corner and both ends (phi = 0, leg B to +y)
        dem = np.maximum(dem, 0.10 - 2.0 * np.hypot(X - p[0], Y - p[1]))
    ga, gb, z0 = resting_plane(dem, g, corner, 0.0, 1.0, 0.0, 0.0)
    # level, on the tussocks' tops (their peaks fall between cell centres: the DEM's maximum)
    assert abs(ga) < 0.01 and abs(gb) < 0.01 and z0 == pytest.approx(dem.max(), abs=0.002)
    assert z0 > 0.05  # not down on the +-2 cm grass as a draped strip


def test_composited_rule_is_straight_and_ends_where_it_ends():
    """A rigid rule 2 cm above a flat grey ground, seen from 4 m: its yellow pixels lie on the
    straight image of each leg and stop at the projected end (within a pixel)."""
    from kitegully.twin.camera import Camera, Pose
    from kitegully.twin.polewalk import composite_rule, look_at

    cam = Camera(width=400, height=300, f=800.0, cx=199.5, cy=149.5)
    C = np.array([0.5, -3.0, 3.0])
    pose = Pose(look_at(C, np.array([0.5, 0.5, 0.0])), C)
    rule = np.array([[1.0, 0.0, 0.02], [0.0, 0.0, 0.02], [0.0, 1.0, 0.02]])
    refl = np.full((300, 400, 3), 0.3, np.float32)
    depth = np.full((300, 400), np.nan, np.float32)
    composite_rule(refl, depth, cam, pose, rule, np.array([0.0, 0.0, 1.0]), 0.3)
    yellow = (refl[..., 0] - refl[..., 2] > 0.2)
    assert yellow.sum() > 100
    uv = cam.project(rule, pose)
    vv, uu = np.nonzero(yellow)
    P = np.column_stack([uu, vv]).astype(float)
    def cross2(a, b):
        return a[0] * b[:, 1] - a[1] * b[:, 0]

    d = np.stack([np.abs(cross2(uv[k] - uv[1], P - uv[1])) / np.linalg.norm(uv[k] - uv[1]) for k in (0, 2)]).min(axis=0)
    assert d.max() < 4.0  # 2 cm at ~4 m = 4 px wide: within its half width + 2 px
    for k in (0, 2):
        e = (uv[k] - uv[1]) / np.linalg.norm(uv[k] - uv[1])
        t = (P - uv[1]) @ e
        on_leg = np.abs(cross2(e, P - uv[1])) < 2.5
        assert t[on_leg].max() == pytest.approx(np.linalg.norm(uv[k] - uv[1]), abs=1.5)
    # behind the terrain (depth nearer than the rule) it is not drawn
    refl2 = np.full((300, 400, 3), 0.3, np.float32)
    composite_rule(refl2, np.full((300, 400), 1.0, np.float32), cam, pose, rule, np.array([0.0, 0.0, 1.0]), 0.3)
    assert np.allclose(refl2, 0.3)
