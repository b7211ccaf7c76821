"""Time and peak memory of ``crowns.interpolate_under`` at full size (issue 21).

An 80 M-cell grid (``kamech_full``'s 10 600 x 7 500 cells at 0.2 m) on a tilted plane with
5 cm noise; shrub crowns are discs of 6 cells (1.2 m) radius around random seeds, ~19 % of the
cells at the default 150 000 seeds (the default twin has 15-23 % under crowns).

    .venv/bin/python benchmarks/crowns_interpolation_scale.py [n_seeds]
"""
import time, resource, sys
import numpy as np
from scipy import ndimage as ndi
from kitegully.gully.crowns import interpolate_under
h, w = 7500, 10600
rng = np.random.default_rng(0)
n_seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 600_000
seeds = np.zeros((h, w), bool)
seeds[rng.integers(0, h, n_seeds), rng.integers(0, w, n_seeds)] = True
dist = ndi.distance_transform_edt(~seeds)
radius = 6.0  # cells (1.2 m at 0.2 m): shrub crowns 1-3 m across
mask = dist <= radius
del dist, seeds
yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
z = (0.01 * xx + 0.02 * yy).astype(np.float64) + rng.normal(0, 0.05, (h, w))
del yy, xx
lab, ng = ndi.label(mask)
sizes = np.bincount(lab.ravel())[1:]
del lab
print(f"cells under crowns {mask.mean():.1%}, groups {ng}, largest {sizes.max()} cells", flush=True)
t = time.perf_counter()
out, m = interpolate_under(z, mask)
print(f"interpolated {m} cells in {time.perf_counter() - t:.1f} s; peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB", flush=True)
