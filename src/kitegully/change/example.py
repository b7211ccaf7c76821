"""Synthetic epoch-2 DEM of the controlled check (``benchmarks/change_controlled.py``).

The DEM-site example ``config/sites/kamech_dem_change.yaml`` now pairs the default twin's two
photogrammetric DSMs. This module keeps the earlier, labelled variant for the controlled
check: the twin's epoch-2 **truth** DSM plus a stated photogrammetric noise model:

``z₂(x) = truth₂(x − Δ) + b + t·(x − x̄) + n_white + n_corr``

with Δ a horizontal georeferencing shift, b a vertical bias, t a tilt (m/m in x and y),
n_white ~ N(0, σ_w²) per cell and n_corr a Gaussian random field of SD σ_c and Gaussian
correlation length λ. Cells where the truth is nodata stay nodata.

Run: ``python -m kitegully.change.example --twin results/kamech_twin --out results/kamech_dem_change/inputs``.
"""

from __future__ import annotations

import argparse
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from kitegully.change.dod import resample
from kitegully.io.raster import Raster
from kitegully.seeds import rng_for

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NoiseModel:
    """Stated noise of the synthetic epoch-2 DEM (all [I]).

    Attributes
    ----------
    shift_x_m, shift_y_m : float
        Horizontal georeferencing shift Δ (m): about 1.5 cells, a GCP-bundle error.
    bias_m : float
        Vertical bias b (m).
    tilt_x, tilt_y : float
        Tilt (m per m): 0.1 m/km, a weak GCP geometry.
    white_sd_m : float
        Per-cell noise σ_w (m): the NMAD of epoch 1's dense DSM against its truth (0.05 m).
    corr_sd_m, corr_length_m : float
        Spatially correlated noise σ_c (m) and its Gaussian correlation length λ (m).
    seed : int
    """

    shift_x_m: float = 0.30
    shift_y_m: float = -0.20
    bias_m: float = 0.08
    tilt_x: float = 1.0e-4
    tilt_y: float = -5.0e-5
    white_sd_m: float = 0.05
    corr_sd_m: float = 0.03
    corr_length_m: float = 20.0
    seed: int = 2018


def noisy_dem(truth: Raster, nm: NoiseModel) -> np.ndarray:
    """``truth`` seen through the noise model (same grid). O(cells)."""
    g = truth.grid
    z = resample(truth, g, -nm.shift_x_m, -nm.shift_y_m)  # truth(x − Δ)
    xs, ys = g.cell_centres()
    z = z + nm.bias_m + nm.tilt_x * (xs[None, :] - xs.mean()) + nm.tilt_y * (ys[:, None] - ys.mean())
    white = rng_for(nm.seed, "change", "example", "white").standard_normal(z.shape)
    field = ndimage.gaussian_filter(rng_for(nm.seed, "change", "example", "corr").standard_normal(z.shape),
                                    nm.corr_length_m / g.cell / np.sqrt(2), mode="wrap")
    field *= nm.corr_sd_m / field.std()
    return (z + nm.white_sd_m * white + field).astype(np.float32)


def export_epoch(truth_dsm: str | Path, out_path: str | Path, nm: NoiseModel) -> Path:
    """Write ``truth_dsm`` seen through ``nm`` to ``out_path`` and the model beside it (``.json``).

    Parameters
    ----------
    truth_dsm : str or Path
        The truth DSM (GeoTIFF).
    out_path : str or Path
        The noisy DEM to write (GeoTIFF); its folder is created.
    nm : NoiseModel
        The noise model.

    Returns
    -------
    Path
        ``out_path``.
    """
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    t = Raster.read(truth_dsm)
    Raster(noisy_dem(t, nm), t.grid).write(out, tags={
        "units": "m", "source": f"{truth_dsm} + stated noise model (kitegully.change.example)"})
    out.with_suffix(".json").write_text(json.dumps(asdict(nm), indent=2) + "\n", encoding="utf-8")
    return out


def export_epoch2(truth_dsm: str | Path, out_dir: str | Path, nm: NoiseModel = NoiseModel()) -> Path:
    """Write ``epoch2_dsm.tif`` (and ``epoch2_dsm.json``, the noise model) into ``out_dir``.

    Parameters
    ----------
    truth_dsm : str or Path
        The twin's epoch-2 truth DSM (GeoTIFF).
    out_dir : str or Path
        Folder to write into; it is created.
    nm : NoiseModel
        The noise model (default: :class:`NoiseModel`'s defaults).

    Returns
    -------
    Path
        The written ``epoch2_dsm.tif``.
    """
    return export_epoch(truth_dsm, Path(out_dir) / "epoch2_dsm.tif", nm)



#: Epoch 1 of the controlled check (benchmarks/change_controlled.py): the same noise, no
#: georeferencing error, another seed; then both epochs' errors follow the stated model.
CONTROLLED_EPOCH1 = NoiseModel(shift_x_m=0.0, shift_y_m=0.0, bias_m=0.0, tilt_x=0.0, tilt_y=0.0, seed=2017)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--twin", default="results/kamech_twin", help="the default twin's results folder")
    ap.add_argument("--out", default="results/kamech_dem_change/inputs")
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO)
    print(export_epoch2(Path(a.twin) / "twin/epoch2/truth/dsm.tif", a.out))
