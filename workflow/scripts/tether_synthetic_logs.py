"""Rule tether_synthetic_logs: camera and operator GPS logs simulated from the line model (twin sites)."""

from kitegully.logs import setup_script_logging
from kitegully.seeds import rng_for
from kitegully.tether.config import atmosphere_from_config, synthetic_flights_from_config
from kitegully.tether.gps import simulate_flight_logs, write_gpx

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.cfg
flights, settings = synthetic_flights_from_config(cfg)
atm = atmosphere_from_config(cfg)
for flight, cam_path, op_path in zip(flights, snakemake.output.camera, snakemake.output.operator):
    rng = rng_for(snakemake.params.seed, "tether", "gps", flight.name)
    camera, operator = simulate_flight_logs(flight, settings, atm, rng)
    write_gpx(camera, cam_path, snakemake.params.crs, f"{flight.name} camera")
    write_gpx(operator, op_path, snakemake.params.crs, f"{flight.name} operator")
    log.info("%s: %d operator fixes, %d camera fixes (kite %s, %s, %.1f m/s)", flight.name, len(operator), len(camera),
             flight.kite.name, flight.material.name, flight.mean_wind_m_s)
