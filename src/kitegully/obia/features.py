"""Segmentation features: z-normalised bands stacked as (rows, cols, k)."""

from __future__ import annotations

import numpy as np


def normalise_features(layers: list[np.ndarray], valid: np.ndarray | None = None) -> np.ndarray:
    """Stack layers and z-normalise each over the valid cells: (v - mean) / SD [I].

    This is what SAGA's "normalize" option does.  A layer with zero spread becomes 0.
    Invalid cells (``valid`` False or any layer NaN) are set to 0 and must be masked by
    the caller.

    Returns
    -------
    numpy.ndarray
        float32 array of shape (rows, cols, len(layers)).
    """
    stack = np.stack([np.asarray(layer, dtype=np.float32) for layer in layers], axis=-1)
    ok = np.all(np.isfinite(stack), axis=-1)
    if valid is not None:
        ok &= valid
    out = np.zeros_like(stack)
    if not ok.any():
        return out
    for k in range(stack.shape[-1]):
        v = stack[..., k]
        m = float(v[ok].mean())
        s = float(v[ok].std())
        out[..., k] = np.where(ok, (v - m) / s if s > 0 else 0.0, 0.0)
    return out
