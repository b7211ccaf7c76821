"""Time and peak memory of ``crowns.interpolate_under`` at full size (issue 21).

An 80 M-cell grid (``kamech_full``'s 10 600 x 7 500 cells at 0.2 m) on a tilted plane with
5 cm noise; shrub crowns are discs of 6 cells (1.2 m) radius around random seeds, ~19 % of the
cells at the default 150 000 seeds (the default twin has 15-23 % under crowns).

    .venv/bin/python benchmarks/crowns_interpolation_scale.py [--seeds 150000]
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np
from scipy import ndimage as ndi

from kitegully.gully.crowns import interpolate_under

HEIGHT, WIDTH = 7500, 10600  # kamech_full at 0.2 m
CROWN_RADIUS_CELLS = 6.0  # 1.2 m at 0.2 m: shrub crowns 1-3 m across


def crown_grid(n_seeds: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A noisy tilted plane and a mask of crown discs around ``n_seeds`` random cells."""
    rng = np.random.default_rng(seed)
    seeds = np.ones((HEIGHT, WIDTH), bool)
    seeds[rng.integers(0, HEIGHT, n_seeds), rng.integers(0, WIDTH, n_seeds)] = False
    mask = ndi.distance_transform_edt(seeds) <= CROWN_RADIUS_CELLS
    rows, cols = np.ogrid[0:HEIGHT, 0:WIDTH]
    z = 0.02 * rows + 0.01 * cols + rng.normal(0.0, 0.05, (HEIGHT, WIDTH))
    return z, mask


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=150_000, help="crown centres")
    args = ap.parse_args()
    z, mask = crown_grid(args.seeds)
    labels, n_groups = ndi.label(mask)
    largest = np.bincount(labels.ravel())[1:].max()
    del labels
    print(f"cells under crowns {mask.mean():.1%}, groups {n_groups}, largest {largest} cells", flush=True)
    start = time.perf_counter()
    _, n = interpolate_under(z, mask)
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"interpolated {n} cells in {time.perf_counter() - start:.1f} s; peak RSS {peak_gb:.2f} GB", flush=True)


if __name__ == "__main__":
    main()
