"""Error budget of a twin's whole-site net volume (evaluation only: reads the twin's truth).

Splits the error of the raw DoD's net volume, E = Σ (DoD − true change)·a over the cells the
budget counts, into parts with a physical cause:

* ``gross`` : cells whose error exceeds 1 m (wrong matches, not a σ of centimetres);
* ``vegetation`` : shrub and tree cells (the twin's land cover), the DSM there is the dense
  matcher's smoothed canopy in both epochs, not the ground;
* ``buildings_water`` : buildings and the reservoir;
* ``ground_offset`` : ground cells × the mean error left on the co-registration's own stable
  cells (the offset the fit could not take out);
* ``ground_deformation`` : the rest on ground cells: the epoch-2 block's non-planar height
  error (co-registration removes a plane fitted on ~10 % of the site) and correlated noise.

and, per GCD threshold, the true change the threshold dropped (Σ true over cells set to 0)
against the error of the cells it kept. ``--voids`` also books the cells the change stage
left out as voids (low matching correlation) by comparing with a DoD made without them.

Usage: ``python benchmarks/change_error_budget.py --site kamech_twin [--before OTHER/dod.tif] [--change-dir DIR]``
→ ``error_budget.csv`` (+ .md) in the change folder judged.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.change.dod import resample  # noqa: E402
from kitegully.change.params import THRESHOLD_METHODS  # noqa: E402
from kitegully.io.raster import Raster  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402

GROSS_M = 1.0
VEGETATION = ("shrub", "tree")
BUILT_WATER = ("building", "water")


def error_budget(res: Path, before: Path | None = None, change_dir: Path | None = None) -> pd.DataFrame:
    """Rows ``part, area_m2, error_m3, error_pct_of_true`` (see module docstring).

    ``res``: the twin's results folder (truth); ``change_dir``: the change products to judge
    (default ``res/change``).
    """
    ch = change_dir or res / "change"
    d = Raster.read(ch / "dod.tif")
    g, dod = d.grid, d.data.astype(np.float64)
    a = g.cell**2
    true = resample(Raster.read(res / "twin/epoch2/truth/dsm.tif"), g).astype(np.float64) - resample(
        Raster.read(res / "twin/truth/dsm.tif"), g)
    lc = resample(Raster.read(res / "twin/truth/landcover.tif"), g)
    names = dict(pd.read_csv(res / "twin/truth/landcover_classes.csv")[["code", "name"]].values)
    codes = {n: c for c, n in names.items()}
    stable = Raster.read(ch / "stable_ground.tif").data == 1
    ok = np.isfinite(dod) & np.isfinite(true)
    e = dod - true
    tn = float(true[ok].sum() * a)

    def row(part, m, err=None):
        err = float(e[m].sum() * a) if err is None else err
        return dict(part=part, area_m2=float(m.sum() * a), error_m3=err, error_pct_of_true=100 * err / abs(tn))

    gross = ok & (np.abs(e) > GROSS_M)
    veg = ok & ~gross & np.isin(lc, [codes[n] for n in VEGETATION if n in codes])
    bw = ok & ~gross & np.isin(lc, [codes[n] for n in BUILT_WATER if n in codes])
    ground = ok & ~gross & ~veg & ~bw
    off = float(np.mean(e[stable & ok & ~gross])) if (stable & ok).any() else 0.0
    rows = [dict(part="true net (counted cells)", area_m2=float(ok.sum() * a), error_m3=tn, error_pct_of_true=np.nan),
            row("total error (raw DoD)", ok)]
    if before is not None and before.exists():
        b = Raster.read(before).data.astype(np.float64)
        okb = np.isfinite(b) & np.isfinite(true)
        tb = float(true[okb].sum() * a)
        rows.append(dict(part="total error before voids (other DoD)", area_m2=float(okb.sum() * a),
                         error_m3=float((b - true)[okb].sum() * a), error_pct_of_true=100 * float((b - true)[okb].sum() * a) / abs(tb)))
        vo = okb & ~ok
        rows.append(row("  voids: cells left out (their error in the other DoD)", vo, float((b - true)[vo].sum() * a)))
    rows += [row(f"  gross (|error| > {GROSS_M:g} m)", gross), row("  vegetation (shrub, tree)", veg),
             row("  buildings, water", bw),
             row(f"  ground: co-registration offset left on stable cells ({1000 * off:+.1f} mm) x ground area", ground,
                 off * float(ground.sum()) * a),
             row("  ground: rest (non-planar epoch-2 height error, correlated noise)", ground,
                 float(e[ground].sum() * a) - off * float(ground.sum()) * a)]
    for m in THRESHOLD_METHODS:
        t = Raster.read(ch / f"dod_thresholded_{m}.tif").data.astype(np.float64)
        kept = ok & (t != 0)
        rows.append(row(f"threshold {m}: total error", ok, float((t[ok] - true[ok]).sum() * a)))
        rows.append(row(f"  {m}: true change dropped (set to 0)", ok & ~kept, -float(true[ok & ~kept].sum() * a)))
        rows.append(row(f"  {m}: error of kept cells", kept))
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="kamech_twin")
    ap.add_argument("--before", type=Path, default=None, help="a DoD of the same pair without voids (optional)")
    ap.add_argument("--change-dir", type=Path, default=None, help="change products to judge (default results/<site>/change)")
    a = ap.parse_args()
    res = REPO / "results" / a.site
    df = error_budget(res, a.before, a.change_dir)
    write_table(df, (a.change_dir or res / "change") / "error_budget.csv")
    with pd.option_context("display.width", 200, "display.max_colwidth", 90):
        print(df.round(1).to_string(index=False))


if __name__ == "__main__":
    main()
