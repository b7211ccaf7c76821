"""Skeleton vectorisation: one node per junction, paths between them."""

import numpy as np

from kitegully.polygons.skeleton import skeleton_paths


def test_a_t_junction_is_one_node_with_three_paths():
    sk = np.zeros((10, 30), bool)
    sk[5, 2:28] = True
    sk[6:9, 10] = True
    paths = skeleton_paths(sk)
    # the diagonal steps beside the junction pixel are staircase shortcuts, not links of their own:
    # with them the junction was a triangle of three nodes and the paths were cut into six
    assert sorted(len(r) for r, _ in paths) == [4, 9, 18]
    assert all((r[0], c[0]) == (5, 10) or (r[-1], c[-1]) == (5, 10) for r, c in paths)


def test_a_diagonal_line_keeps_its_diagonal_steps():
    sk = np.eye(12, dtype=bool)
    paths = skeleton_paths(sk)
    assert len(paths) == 1 and len(paths[0][0]) == 12


def test_a_y_junction_of_diagonal_branches_is_one_node():
    sk = np.zeros((20, 20), bool)
    sk[10:19, 10] = True  # stem down
    for i in range(1, 8):
        sk[10 - i, 10 - i] = True  # branch up-left
        sk[10 - i, 10 + i] = True  # branch up-right
    paths = skeleton_paths(sk)
    assert sorted(len(r) for r, _ in paths) == [8, 8, 9]


def test_a_single_pixel_skeleton_has_no_path_and_is_not_an_error():
    # A round polygon thins to one pixel; the diagonal-shortcut step used to raise on a graph
    # without edges (sparse fancy indexing with no index returns a sparse matrix).
    skel = np.zeros((5, 5), bool)
    skel[2, 2] = True
    assert skeleton_paths(skel, min_cells=1) == []
