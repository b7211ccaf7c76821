"""Rule tether_synthetic_logs: camera and operator GPS logs simulated from the line model (twin sites)."""

from kitegully.logs import setup_script_logging
from kitegully.tether.gps import write_gpx
from kitegully.tether import TetherParams, synthetic_gps_logs

log = setup_script_logging(snakemake.log[0])
crs = snakemake.params.crs
logs = synthetic_gps_logs(TetherParams.from_config(snakemake.params.cfg), snakemake.params.seed)
for (name, camera, operator), cam_path, op_path in zip(logs, snakemake.output.camera, snakemake.output.operator):
    write_gpx(camera, cam_path, crs, f"{name} camera")
    write_gpx(operator, op_path, crs, f"{name} operator")
