"""Where a constructed folding rule lies on the ground (shared by the rule tests)."""

from __future__ import annotations

import numpy as np


def rule_cells(X: np.ndarray, Y: np.ndarray, corner: np.ndarray, legs) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per leg (3-D unit vector along it), the painted 2 cm strip and its 1 cm black decimetre marks at ground (X, Y).

    Returns one ``(paint, mark)`` pair of boolean arrays per leg; a leg is 1 m long in 3-D.
    """
    out = []
    for t in legs:
        e = t[:2] / np.linalg.norm(t[:2])
        plan = np.linalg.norm(t[:2])
        along = (X - corner[0]) * e[0] + (Y - corner[1]) * e[1]
        across = -(X - corner[0]) * e[1] + (Y - corner[1]) * e[0]
        on = (along >= -0.01) & (along <= plan) & (np.abs(across) <= 0.01)
        leg = along / plan
        out.append((on, on & (np.abs(leg - np.round(leg, 1)) <= 0.005)))
    return out
