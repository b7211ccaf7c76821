"""Rule tether_simulation: line shapes (Fig. 5), flight angle vs line length (Fig. 6), Table 2 check."""

import numpy as np

from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.tether.analysis import flight_angle_table, table2_comparison
from kitegully.tether.config import atmosphere_from_config, kites_from_config, materials_from_config, sweep_lengths
from kitegully.tether.line import KiteModel, solve_line
from kitegully.tether.plots import plot_flight_angle_vs_length, plot_line_shapes

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.cfg
materials = materials_from_config(cfg)
kite = kites_from_config(cfg)[cfg["simulation_kite"]]
atm = atmosphere_from_config(cfg)
ds = cfg["segment_length_m"]
winds = cfg["sweep"]["winds_m_s"]
log.info("kite %s, pull-angle reading %s, winds %s m/s", kite.name, kite.model.value, winds)

table = flight_angle_table(materials, kite, winds, sweep_lengths(cfg), atm, ds)
write_table(table, snakemake.output.table)
for (material, wind), s in table[table["line_length_m"] > 0].groupby(["material", "wind_m_s"]):
    flying = s[s["flies"]]
    log.info(
        "%-10s %4.1f m/s: angle %.1f° at %g m -> %.1f° at %g m; %s",
        material, wind,
        flying["flight_angle_deg"].iloc[0] if len(flying) else np.nan, s["line_length_m"].min(),
        flying["flight_angle_deg"].iloc[-1] if len(flying) else np.nan, flying["line_length_m"].max() if len(flying) else np.nan,
        "line touches the ground beyond that" if (s["status"] != "flying").any() else "whole line airborne",
    )

shape_length = cfg["sweep"]["shape_line_length_m"]
solutions = {
    name: solve_line(m, kite, winds, shape_length, atm, ds)
    for name, m in materials.items()
    if name != cfg["reference_line"]
}
reference = solve_line(materials[cfg["reference_line"]], kite, winds, shape_length, atm, ds)
plot_line_shapes(solutions, reference, shape_length, snakemake.output.shapes)
plot_flight_angle_vs_length(table, snakemake.output.angles, reference_material=cfg["reference_line"])

t2 = cfg["table2"]
all_kites = {
    f"{reading.value} [{'I-A' if reading is KiteModel.BRIDLE_TENSION else 'I-B'}]": kites_from_config(cfg, reading.value)[cfg["simulation_kite"]]
    for reading in KiteModel
}
comparison = table2_comparison(
    materials[t2["material"]], all_kites, t2["winds_m_s"], t2["line_lengths_m"], t2["flying_heights_m"], atm, ds
)
comparison["within_tolerance"] = comparison["difference_pct"].abs() <= t2["tolerance_pct"]
write_table(comparison, snakemake.output.table2)
for reading, s in comparison.groupby("reading"):
    log.info(
        "Table 2 under %s: %d of %d heights within %g%% (differences %.1f%% to %.1f%%)",
        reading, int(s["within_tolerance"].sum()), len(s), t2["tolerance_pct"],
        s["difference_pct"].min(), s["difference_pct"].max(),
    )
