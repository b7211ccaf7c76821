"""Rule tether_observed_angles: effective flight angles from paired GPS logs (Fig. 7)."""

from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.tether.plots import plot_observed_flight_angles
from kitegully.tether import TetherParams, observed_flight_angles

log = setup_script_logging(snakemake.log[0])
res = observed_flight_angles(TetherParams.from_config(snakemake.params.cfg), snakemake.input.camera, snakemake.input.operator, snakemake.params.crs)
write_table(res.fixes, snakemake.output.fixes, markdown=False)
write_table(res.summary, snakemake.output.summary)
plot_observed_flight_angles(res.summary, res.simulated, snakemake.output.figure)
