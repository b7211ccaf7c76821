"""Reading a scene's photographs: the prepared copies SfM saw, and the photographer's originals."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Mapping, Sequence

import cv2
import numpy as np

from kitegully import InputError


def read_photos(photo_dir: Path, names: Sequence[str]) -> dict[str, np.ndarray]:
    out = {}
    for n in names:
        img = cv2.imread(str(photo_dir / n), cv2.IMREAD_COLOR)
        if img is None:
            raise InputError(f"{photo_dir / n}: cannot read the photo")
        out[n] = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return out


def original_photos(photo_dir: Path, image_info_path: str | Path, prepared: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The photographer's files where they are the SfM's pixel grid (orientation 1, scale 1), else the prepared copies.

    The prepared copies (:func:`kitegully.sfm.images.prepare_images`) are re-encoded with
    4:2:0 chroma subsampling, which halves the colour resolution: a 1–2 px yellow strip
    loses most of its colour there (scene 09: no L in any prepared copy, L's in the
    originals), while the originals (4:4:4 at quality 95) keep it.  The sphere detection
    keeps the prepared copies (not changed here).
    """
    with open(image_info_path, encoding="utf-8") as fh:
        info = {r["sfm_name"]: r for r in json.load(fh)}
    out = {}
    for name, img in prepared.items():
        r = info.get(name)
        if r is not None and int(r.get("orientation", 1)) == 1 and float(r.get("scale", 1.0)) == 1.0:
            orig = cv2.imread(str(photo_dir / r["name"]), cv2.IMREAD_COLOR)
            if orig is not None and orig.shape[:2] == img.shape[:2]:
                out[name] = cv2.cvtColor(orig, cv2.COLOR_BGR2RGB)
                continue
        out[name] = img
    return out
