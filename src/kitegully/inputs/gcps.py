"""Ground-control and checkpoint files: format, coordinates, heights, duplicates, image names, pixels."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from pyproj import CRS

from kitegully import InputError
from kitegully.georef.gcp_io import parse_projection, read_gcps
from kitegully.inputs.findings import Findings
from kitegully.inputs.photos import Photo
from kitegully.inputs.points import Z_UNITS, check_heights, check_points, duplicate_lines

# [I] Half a pixel of rounding plus one pixel of slack at the image edge.
EDGE_SLACK_PX = 1.5
# Scales tried when pixels fall outside the image at the declared one: full resolution
# and the usual downsampled copies people click on.
CANDIDATE_SCALES = (1.0, 0.5, 0.25)


@dataclass(frozen=True)
class GcpRows:
    """Rows of a GCP file as written: one observation (x, y, z, px, py, image, name) per line."""

    crs: CRS
    lines: list[int]
    xyz: np.ndarray
    pixels: np.ndarray
    images: list[str]
    names: list[str]


def _odm_rows(path: Path) -> GcpRows:
    text = path.read_text(encoding="utf-8-sig").splitlines()
    lines = [(i + 1, ln.strip()) for i, ln in enumerate(text)]
    lines = [(i, ln) for i, ln in lines if ln and not ln.startswith("#")]
    crs = parse_projection(lines[0][1], path)
    nums, images, names, linenos = [], [], [], []
    for i, ln in lines[1:]:
        p = ln.split()
        nums.append([float(v) for v in p[:5]])
        images.append(p[5])
        names.append(p[6] if len(p) > 6 else "")
        linenos.append(i)
    a = np.array(nums, float).reshape(-1, 5)
    return GcpRows(crs, linenos, a[:, :3], a[:, 3:5], images, names)


def _csv_rows(path: Path, crs: CRS) -> GcpRows:
    df = pd.read_csv(path)
    a = df[["x", "y", "z", "px", "py"]].apply(pd.to_numeric).to_numpy(float)
    return GcpRows(crs, [k + 2 for k in range(len(df))], a[:, :3], a[:, 3:5], [str(v) for v in df["image"]],
                   [str(v) for v in df["gcp_id"]])


def gcp_format_of(path: str | Path, fmt: str) -> str:
    """``odm`` or ``csv``: ``fmt`` unless ``auto`` (then by suffix), as :func:`read_gcps` decides."""
    if fmt == "auto":
        return "csv" if Path(path).suffix.lower() == ".csv" else "odm"
    return fmt


def check_gcp_file(
    path: str | Path, site_crs: CRS, fmt: str, csv_crs: str | None, pixel_frame: str, pixel_scale: float,
    z_units: str, photos: list[Photo], found: Findings,
) -> GcpRows | None:
    """Check a GCP file against its CRS, the photographs and itself; record findings.

    Returns the rows as written (None when the file cannot be read).

    Parameters
    ----------
    path : str or Path
        The GCP file.
    site_crs : CRS
        The site CRS; the CRS of a CSV file unless ``csv_crs`` is given.
    fmt : str
        ``odm``, ``csv`` or ``auto`` (by suffix: ``.csv`` is CSV, anything else ODM).
    csv_crs : str or None
        CRS of a CSV file; None: the site CRS.
    pixel_frame : str
        ``stored`` or ``display``: the frame the file's pixels refer to.
    pixel_scale : float
        Pixels of the file per stored pixel.
    z_units : str
        Units of the heights: ``m``, ``ft`` or ``us_ft``.
    photos : list of Photo
        The photographs; image names and pixels are checked against them, heights against their
        EXIF GPS altitude.
    found : Findings
        Collects the findings and facts.

    Returns
    -------
    GcpRows or None
    """
    path = Path(path)
    src = str(path)
    fmt = gcp_format_of(path, fmt)
    try:
        if not path.is_file():
            raise InputError(f"{path}: GCP file not found")
        if fmt == "odm":
            head = next((ln.strip() for ln in path.read_text(encoding="utf-8-sig").splitlines()
                         if ln.strip() and not ln.strip().startswith("#")), "")
            file_crs = parse_projection(head, path) if head else None
        else:
            file_crs = CRS.from_user_input(csv_crs) if csv_crs else site_crs
        # format check in the file's own CRS (no reprojection yet)
        read_gcps(path, file_crs.to_wkt() if file_crs is not None else site_crs.to_wkt(), fmt, None)
        rows = _odm_rows(path) if fmt == "odm" else _csv_rows(path, file_crs)
    except InputError as exc:
        found.error(src, str(exc).removeprefix(f"{path}: "))
        return None
    ok = check_points(rows.crs, rows.xyz[:, 0], rows.xyz[:, 1], rows.lines, photos, found, src, "GCP")
    if ok:
        check_heights(rows.xyz[:, 2], z_units, photos, found, src, "GCP")
    keys = [tuple(r) + (im,) for r, im in zip(np.column_stack([rows.xyz, rows.pixels]).round(6).tolist(), rows.images)]
    dups = duplicate_lines(keys, rows.lines)
    if dups:
        found.error(src, f"duplicate row(s): line {dups[0][1]} repeats line {dups[0][0]}"
                         + (f" (and {len(dups) - 1} more)" if len(dups) > 1 else "") + "; remove the repeats")
    n_gcps = len({n or f"{x:.3f}_{y:.3f}" for n, (x, y, _) in zip(rows.names, rows.xyz)})
    found.facts.update(gcp_file=src, gcp_crs=rows.crs.to_string(), n_gcps=n_gcps, n_gcp_observations=len(rows.lines))
    if n_gcps < 3:
        found.error(src, f"only {n_gcps} GCP(s); georeferencing needs at least 3")
    if photos:
        _check_images(rows, photos, pixel_frame, pixel_scale, found, src)
    return rows


def _check_images(rows: GcpRows, photos: list[Photo], frame: str, scale: float, found: Findings, src: str) -> None:
    by_name = {p.name: p for p in photos}
    by_lower = {p.name.lower(): p.name for p in photos}
    near, missing = [], []
    for ln, im in zip(rows.lines, rows.images):
        if im in by_name:
            continue
        if im.lower() in by_lower:
            near.append((ln, im, by_lower[im.lower()]))
        else:
            missing.append((ln, im))
    if near:
        ln, im, real = near[0]
        found.error(src, f"line {ln}: image '{im}' is not in the photo folder, but '{real}' is (the names differ only in "
                         f"upper/lower case); write the names exactly as the files are named"
                         + (f" ({len(near)} rows affected)" if len(near) > 1 else ""))
        return
    if missing and len(missing) == len(rows.lines):
        found.error(src, f"none of the images the file names is in the photo folder (e.g. '{missing[0][1]}' on line {missing[0][0]})")
        return
    if missing:
        names = sorted({m[1] for m in missing})
        found.warning(src, f"{len(missing)} observation(s) name images that are not in the photo folder and are ignored: {', '.join(names[:5])}")
    idx = [k for k, im in enumerate(rows.images) if im in by_name]
    sizes = np.array([by_name[rows.images[k]].size_in(frame) for k in idx], float)
    px = rows.pixels[idx]
    ratio = np.max(px / sizes, axis=1)  # the smallest scale at which each point is inside its image
    limit = scale + EDGE_SLACK_PX / sizes.max(axis=1)
    out = ratio > limit
    if not out.any():
        return
    k = int(np.argmax(ratio))
    w, h = sizes[k]
    need = float(ratio.max())
    fits = [s for s in CANDIDATE_SCALES if need <= s + EDGE_SLACK_PX / max(w, h)]
    other = "display" if frame == "stored" else "stored"
    other_sizes = np.array([by_name[rows.images[j]].size_in(other) for j in idx], float)
    other_ok = bool(np.all(np.max(px / other_sizes, axis=1) <= limit))
    best = min(fits) if fits else None
    fit_txt = (f"they fit inside the images at gcp_pixel_scale {best:g}{' (full resolution)' if best == 1.0 else ''}" if fits
               else "they fit at no usual scale") + f" (the smallest scale that holds them all is {need:.4f})"
    if other_ok:
        fit_txt = f"they fit in the {other} (EXIF-{'rotated' if other == 'display' else 'unrotated'}) frame at the declared scale; set georef.gcp_pixel_frame: {other}"
    found.error(src, f"line {rows.lines[idx[k]]}: pixel ({px[k, 0]:.0f}, {px[k, 1]:.0f}) on {rows.images[idx[k]]} lies outside its "
                     f"{w * scale:.0f} x {h * scale:.0f} px at georef.gcp_pixel_scale {scale:g} ({int(out.sum())} point(s) outside); {fit_txt}")


def write_gcp_copy(path: str | Path, out: str | Path, fmt: str, z_units: str) -> None:
    """Copy the GCP file to ``out`` with heights converted to metres (a plain copy when already in metres).

    Parameters
    ----------
    path : str or Path
        The GCP file.
    out : str or Path
        The copy.
    fmt : str
        ``odm``, ``csv`` or ``auto`` (by suffix).
    z_units : str
        Units of the heights in ``path``: ``m``, ``ft`` or ``us_ft``.
    """
    path, out = Path(path), Path(out)
    factor = Z_UNITS[z_units]
    if factor == 1.0:
        out.write_bytes(path.read_bytes())
        return
    if gcp_format_of(path, fmt) == "csv":
        df = pd.read_csv(path)
        df["z"] = pd.to_numeric(df["z"]) * factor
        df.to_csv(out, index=False)
        return
    lines, header_seen = [], False
    for ln in path.read_text(encoding="utf-8-sig").splitlines():
        s = ln.strip()
        if not s or s.startswith("#") or not header_seen:
            header_seen = header_seen or bool(s and not s.startswith("#"))
            lines.append(ln)
            continue
        p = s.split()
        p[2] = f"{float(p[2]) * factor:.4f}"
        lines.append(" ".join(p))
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")


def check_checkpoints(path: str | Path, site_crs: CRS, z_units: str, photos: list[Photo], found: Findings) -> pd.DataFrame | None:
    """Checkpoint CSV ``id,x,y,z`` in the site CRS: columns, numbers, coordinates, heights, duplicates.

    Parameters
    ----------
    path : str or Path
        The checkpoint CSV.
    site_crs : CRS
        The site CRS.
    z_units : str
        Units of the heights: ``m``, ``ft`` or ``us_ft``.
    photos : list of Photo
        The photographs; the points and heights are checked against their EXIF GPS.
    found : Findings
        Collects the findings and facts.

    Returns
    -------
    DataFrame or None
        The table as read; None when it is missing, unreadable, lacks a column or has a bad number.
    """
    path = Path(path)
    src = str(path)
    if not path.is_file():
        found.error(src, "checkpoint file not found")
        return None
    try:
        df = pd.read_csv(path)
    except Exception as exc:  # pandas raises several parser errors
        found.error(src, f"cannot read CSV ({str(exc).splitlines()[0]})")
        return None
    need = ["id", "x", "y", "z"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        found.error(src, f"missing column(s) {', '.join(missing)}; expected {', '.join(need)} (coordinates in the site CRS, m)")
        return None
    num = df[["x", "y", "z"]].apply(pd.to_numeric, errors="coerce")
    bad = num.isna().any(axis=1)
    if bad.any():
        found.error(src, f"line {int(np.flatnonzero(bad.to_numpy())[0]) + 2}: missing or non-numeric coordinate")
        return None
    lines = [k + 2 for k in range(len(df))]
    if check_points(site_crs, num["x"].to_numpy(), num["y"].to_numpy(), lines, photos, found, src, "checkpoint"):
        check_heights(num["z"].to_numpy(), z_units, photos, found, src, "checkpoint")
    ids = df["id"].astype(str).tolist()
    dups = duplicate_lines([(i,) for i in ids], lines)
    if dups:
        found.error(src, f"duplicate checkpoint id '{ids[dups[0][1] - 2]}' on lines {dups[0][0]} and {dups[0][1]}")
    found.facts.update(checkpoint_file=src, n_checkpoints=len(df))
    return df


def write_checkpoint_copy(path: str | Path, out: str | Path, z_units: str) -> None:
    """Copy the checkpoint CSV to ``out`` with heights converted to metres.

    Parameters
    ----------
    path : str or Path
        The checkpoint CSV.
    out : str or Path
        The copy.
    z_units : str
        Units of the heights in ``path``: ``m``, ``ft`` or ``us_ft``.
    """
    df = pd.read_csv(path)
    df["z"] = pd.to_numeric(df["z"]) * Z_UNITS[z_units]
    df.to_csv(out, index=False)
