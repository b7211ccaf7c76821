"""The downstream-forest helpers of kitegully.gully.network."""

import numpy as np


def test_topological_order_puts_every_cell_after_its_inflows():
    from kitegully.gully.network import topological_order

    # two heads (0, 3) joining at 2, then 4 -> 5 outlet; 6 an isolated outlet
    pos_down = np.array([1, 2, 4, 2, 5, -1, -1], np.int64)
    order, indeg = topological_order(pos_down)
    assert sorted(order.tolist()) == list(range(7))
    rank = {c: k for k, c in enumerate(order.tolist())}
    assert all(rank[i] < rank[j] for i, j in enumerate(pos_down.tolist()) if j >= 0)
    assert indeg.tolist() == [0, 1, 2, 0, 1, 1, 0]
