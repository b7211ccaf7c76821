"""Checking a site's inputs before the heavy work (issue 14).

One cheap rule (``check_inputs``) reads every input a site hands in, the photographs, the
GCP file, the checkpoints and any rasters, and refuses the run with one sentence naming
the file and the problem when something is wrong; structure from motion and everything
after depend on it. One module per input kind: :mod:`.crs`, :mod:`.photos`, :mod:`.gcps`
(GCP and checkpoint files, with :mod:`.points`), :mod:`.rasters`; :mod:`.report` writes
``report.md`` and ``report.json``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from kitegully import InputError
from kitegully.inputs.findings import Finding, Findings

__all__ = ["InputSettings", "Finding", "Findings", "check_site_inputs", "check_inputs", "write_report", "write_gcp_copy", "write_checkpoint_copy"]

Z_UNIT_NAMES = ("m", "ft", "us_ft")


def __getattr__(name: str):
    # the writers live in submodules that import pandas and rasterio; importing them lazily
    # keeps `kitegully.inputs.crs` (used when the Snakefile validates the config) light
    if name in ("write_gcp_copy", "write_checkpoint_copy"):
        from kitegully.inputs import gcps

        return getattr(gcps, name)
    if name == "write_report":
        from kitegully.inputs.report import write_report

        return write_report
    raise AttributeError(name)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class InputSettings:
    """How to read a site's inputs.

    Attributes
    ----------
    crs : str
        Site CRS (``site.crs``); must be projected in metres.
    gcp_format : str
        ``odm``, ``csv`` or ``auto`` (``georef.gcp_format``).
    csv_crs : str or None
        CRS of a CSV GCP file (``georef.csv_crs``; the site CRS when None).
    gcp_pixel_frame : str
        ``stored`` or ``display``: the frame the GCP file's pixels refer to.
    gcp_pixel_scale : float
        Pixels of the file per stored pixel (``georef.gcp_pixel_scale``).
    z_units : str
        Units of the heights in the GCP and checkpoint files: ``m``, ``ft`` or ``us_ft``
        (``inputs.z_units``, default ``m``). Converted explicitly, never guessed: heights
        that look like feet under ``m`` are refused.
    rasters : tuple of (str, float or None)
        Rasters handed in (``inputs.rasters``): path and the declared nodata value.
    vectors : tuple of (str, str)
        Vector files handed in and the config key naming each (``gully.heads_file``,
        ``gully.reference_network_file``, ``gully.validation.catchment_file``).
    """

    crs: str
    gcp_format: str = "auto"
    csv_crs: str | None = None
    gcp_pixel_frame: str = "stored"
    gcp_pixel_scale: float = 1.0
    z_units: str = "m"
    rasters: tuple[tuple[str, float | None], ...] = ()
    vectors: tuple[tuple[str, str], ...] = ()

    @classmethod
    def from_config(cls, cfg: dict) -> "InputSettings":
        """Build from ``{"crs": site.crs, "inputs": {...}, "georef": {...}, "vectors": {config key: path}}``."""
        inputs = cfg.get("inputs") or {}
        georef = cfg.get("georef") or {}
        z_units = inputs.get("z_units", "m")
        if z_units not in Z_UNIT_NAMES:
            raise InputError(f"inputs.z_units: '{z_units}' is not one of {', '.join(Z_UNIT_NAMES)}")
        rasters = tuple((str(r["path"]), r.get("nodata")) for r in inputs.get("rasters") or [])
        return cls(
            crs=cfg["crs"], gcp_format=georef.get("gcp_format", "auto"), csv_crs=georef.get("csv_crs"),
            gcp_pixel_frame=georef.get("gcp_pixel_frame", "stored"), gcp_pixel_scale=float(georef.get("gcp_pixel_scale", 1.0)),
            z_units=z_units, rasters=rasters,
            vectors=tuple((str(p), k) for k, p in (cfg.get("vectors") or {}).items() if p),
        )


def check_site_inputs(
    settings: InputSettings,
    images_dir: str | Path,
    gcp_file: str | Path | None = None,
    checkpoints: str | Path | None = None,
) -> Findings:
    """Read every input of a site and say what is wrong with it.

    Parameters
    ----------
    settings
        How to read the inputs (site CRS, GCP format and pixel frame, height units, rasters).
    images_dir
        Folder of the photographs.
    gcp_file
        Ground-control file (None when the site has none).
    checkpoints
        Checkpoint CSV ``id,x,y,z`` (None when there are none).

    Returns
    -------
    Findings
        Errors (the run must stop), warnings, notes and facts, in the order found.
        Cost: one full decode of every photograph plus a decimated read of each raster.
    """
    from kitegully.inputs.crs import site_crs
    from kitegully.inputs.gcps import check_checkpoints, check_gcp_file
    from kitegully.inputs.photos import check_photos
    from kitegully.inputs.rasters import check_raster
    from kitegully.inputs.vectors import check_vector

    found = Findings()
    try:
        crs = site_crs(settings.crs)
    except InputError as exc:
        found.error("site.crs", str(exc).removeprefix("site.crs: "))
        return found
    photos = check_photos(images_dir, found)
    if gcp_file is not None:
        check_gcp_file(gcp_file, crs, settings.gcp_format, settings.csv_crs, settings.gcp_pixel_frame,
                       settings.gcp_pixel_scale, settings.z_units, photos, found)
    if checkpoints is not None:
        check_checkpoints(checkpoints, crs, settings.z_units, photos, found)
    for path, nodata in settings.rasters:
        check_raster(path, crs, nodata, found)
    for path, key in settings.vectors:
        check_vector(path, key, crs, found)
    found.facts.update(site_crs=settings.crs, z_units=settings.z_units)
    for f in found.items:
        getattr(log, {"error": "error", "warning": "warning", "note": "info"}[f.level])("%s", f.line)
    return found


def check_inputs(
    settings: InputSettings, images_dir: str | Path, gcp_file: str | Path, checkpoints: str | Path | None, out: dict, site: str,
) -> Findings:
    """Check the site's inputs, write the report, refuse bad inputs, then write the checked copies.

    ``out`` maps ``report`` (markdown), ``json``, ``gcp`` and, when there are checkpoints,
    ``checkpoints`` to paths. The report is written in any case; the checked GCP and
    checkpoint copies (heights converted to metres) only when there is no error.

    Parameters
    ----------
    settings : InputSettings
        How to read the inputs.
    images_dir : str or Path
        Folder of the photographs.
    gcp_file : str or Path
        Ground-control file.
    checkpoints : str or Path or None
        Checkpoint CSV ``id,x,y,z``; None when there are none.
    out : dict
        Output name → path, as above.
    site : str
        Site name, in the report's title and in ``report.json``.

    Returns
    -------
    Findings
        What :func:`check_site_inputs` found (no error).

    Raises
    ------
    InputError
        The first error's one line (and how many more the log lists).
    """
    from kitegully.inputs.gcps import write_checkpoint_copy, write_gcp_copy
    from kitegully.inputs.report import write_report

    found = check_site_inputs(settings, images_dir, gcp_file, checkpoints)
    write_report(found, out["json"], out["report"], site)
    found.raise_for_errors()
    write_gcp_copy(gcp_file, out["gcp"], settings.gcp_format, settings.z_units)
    if checkpoints is not None:
        write_checkpoint_copy(checkpoints, out["checkpoints"], settings.z_units)
    log.info("inputs accepted: %d warning(s), %d note(s)", len(found.of("warning")), len(found.of("note")))
    return found
