"""Rule report_qgis: QGIS project (.qgs) of the site's products, plain XML."""

from kitegully.io.qgis import write_qgis_project
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
layers = write_qgis_project(
    sm.output.project, sm.params.site, sm.params.crs, dict(sm.input), error_limit_m=sm.params.error_limit_m,
    azimuth_deg=sm.params.shading["azimuth_deg"], altitude_deg=sm.params.shading["altitude_deg"],
    checkpoint_gpkg=sm.output.get("checkpoints"),
)
log.info("QGIS project %s: %s", sm.output.project, ", ".join(f"{lay.name} ({lay.path})" for lay in layers))
