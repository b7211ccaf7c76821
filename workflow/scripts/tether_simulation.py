"""Rule tether_simulation: line shapes (Fig. 5), flight angle vs line length (Fig. 6), Table 2 check."""

from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.tether.plots import plot_flight_angle_vs_length, plot_line_shapes
from kitegully.tether import TetherParams, simulate_tether

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.tether
sim = simulate_tether(TetherParams.from_config(cfg))
write_table(sim.table, snakemake.output.table)
plot_line_shapes(sim.solutions, sim.reference, cfg["sweep"]["shape_line_length_m"], snakemake.output.shapes)
plot_flight_angle_vs_length(sim.table, snakemake.output.angles, reference_material=cfg["reference_line"])
write_table(sim.comparison, snakemake.output.table2)
