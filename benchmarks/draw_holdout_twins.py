#!/usr/bin/env python
"""Draw held-out twins at random inside the ensemble's range and write their site files (issue 15).

The ensemble members (``config/sites/ensemble/``) were chosen by hand to span a range of
difficulty, and methods were written and chosen on them; the held-out twins are an independent
check only if nobody picks them. This script draws each varied parameter uniformly over the range
the ensemble spans, with a fixed random seed, before any run, and writes one overrides file per
twin (the same keys as an ensemble member) into ``--out``:

- grass greenness U(0, 0.9), rounded to 0.05 (ensemble: 0.0 ... 0.9);
- sun elevation U(25, 60) deg, rounded to 5 deg (ensemble: 25 ... 60);
- shrub cover u ~ U(0, 1): ``threshold_gully = 0.05 - 0.10 u``, ``threshold_open = 0.45 - 0.15 u``
  (u = 0: the default shrubs, u = 1: ens4's dense shrubs; lower thresholds = more shrub);
- share of shallow left-bank gullies U(0.5, 0.8), rounded to 0.05;
- digitising accuracy U(2, 4) m per axis, rounded to 0.5 m, and the head snapping radius 3 x it
  (the ensemble's own [I] rule);
- the twin's own seed: 1000 + 101 k for twin hk (101 k alone would repeat the ensemble's seeds).

Usage::

    .venv/bin/python benchmarks/draw_holdout_twins.py --names h3,h4,h5,h6 --seed 20261206
    .venv/bin/python benchmarks/draw_holdout_twins.py --names h27,h28,h29 --seed 20261211 --greenness 0.4,0.7 --shrub-u 0.8,1.0

The second form is a declared stress set: the same draw restricted to a corner of the range where a method
failed on a random twin (session 43: h26), to confirm a fix there; it says so in each file.

The files are committed; rerunning with the same arguments writes the same files.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def draw(rng: np.random.Generator, greenness_range: tuple[float, float] = (0.0, 0.9),
         shrub_range: tuple[float, float] = (0.0, 1.0)) -> dict:
    """One twin's parameters, drawn uniformly over the ensemble's range.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draws.
    greenness_range, shrub_range : tuple of float
        Ranges of the grass greenness and of the shrub cover u; narrower than the ensemble's only for a
        declared stress set (a part of the range where a method failed), never to pick easy twins.

    Returns
    -------
    dict
        ``greenness, sun_deg, shrub_u, threshold_gully, threshold_open, shallow, heads_sigma_m``.
    """
    greenness = round(rng.uniform(*greenness_range) / 0.05) * 0.05
    sun = round(rng.uniform(25.0, 60.0) / 5.0) * 5.0
    u = rng.uniform(*shrub_range)
    shallow = round(rng.uniform(0.5, 0.8) / 0.05) * 0.05
    sigma = round(rng.uniform(2.0, 4.0) / 0.5) * 0.5
    return {"greenness": round(greenness, 2), "sun_deg": int(sun), "shrub_u": round(u, 2),
            "threshold_gully": round(0.05 - 0.10 * u, 3), "threshold_open": round(0.45 - 0.15 * u, 3),
            "shallow": round(shallow, 2), "heads_sigma_m": sigma}


def site_file(name: str, twin_seed: int, p: dict, draw_seed: int, stress: str = "") -> str:
    """The overrides file of one held-out twin (YAML text); ``stress`` names a restricted draw's ranges."""
    kind = f"stress draw, {stress}" if stress else "random draw"
    desc = (f"Kamech-like twin, held-out {name} ({kind}): grass {p['greenness']}, sun {p['sun_deg']} deg, "
            f"shrub cover {p['shrub_u']}, {int(round(p['shallow'] * 100))} % shallow, {p['heads_sigma_m']} m digitising")
    return f"""# Held-out twin {name} (issue 15): overrides on top of config/sites/kamech_twin.yaml, like the ensemble
# members, drawn at random inside {"a declared part of " if stress else ""}the ensemble's range by benchmarks/draw_holdout_twins.py
# (--seed {draw_seed}{(" " + stress) if stress else ""}) before any run, and never used to write or choose a method: an independent
# check of the ensemble's numbers (benchmarks/twin_ensemble.py --member-dir config/sites/holdout).
site:
  name: {name}
  description: "{desc}"
seed: {twin_seed}
twin:
  texture:
    grass_greenness: {p['greenness']}               # 0 dry straw .. 1 green
    illumination: {{gain: 1.0, sun_azimuth_deg: 135.0, sun_elevation_deg: {p['sun_deg']}, shading_strength: 0.6, min_light: 0.15}}
  landcover:
    shrubs: {{height_m: 1.0, wavelength_m: 4.0, threshold_gully: {p['threshold_gully']}, threshold_open: {p['threshold_open']}, ramp: 0.15, min_height_fraction: 0.3}}  # lower thresholds = more shrub
  gullies:
    shallow_share_left: {p['shallow']}             # share of weakly incised left-bank gullies
  survey:
    heads_sigma_m: {p['heads_sigma_m']}                   # digitising accuracy the operator claims (m per axis)
gully:
  head_snap_radius_m: {3 * p['heads_sigma_m']}            # [I] 3 x survey.heads_sigma_m ({p['heads_sigma_m']} m): holds 99 % of 2-D head errors
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--names", required=True, help="comma-separated twin names, e.g. h3,h4")
    ap.add_argument("--seed", type=int, required=True, help="seed of the draw")
    ap.add_argument("--out", default=str(REPO / "config" / "sites" / "holdout"))
    ap.add_argument("--greenness", default=None, metavar="LO,HI", help="stress set: grass greenness range (default 0,0.9)")
    ap.add_argument("--shrub-u", default=None, metavar="LO,HI", help="stress set: shrub cover range (default 0,1)")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    given = [(flag, key, v) for flag, key, v in (("--greenness", "greenness_range", args.greenness),
                                                 ("--shrub-u", "shrub_range", args.shrub_u)) if v]
    stress = " ".join(f"{flag} {v}" for flag, _, v in given)  # as typed, written into each file
    ranges = {key: tuple(float(x) for x in v.split(",")) for _, key, v in given}
    for name in args.names.split(","):
        k = int(name.lstrip("h"))
        p = draw(rng, **ranges)
        path = out / f"{name}.yaml"
        path.write_text(site_file(name, 1000 + 101 * k, p, args.seed, stress))
        print(path.relative_to(REPO) if path.is_relative_to(REPO) else path, p)


if __name__ == "__main__":
    main()
