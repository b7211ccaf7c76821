"""Rule tether_observed_angles: effective flight angles from paired GPS logs (Fig. 7)."""

import pandas as pd

from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.tether.analysis import flight_angle_table
from kitegully.tether.config import atmosphere_from_config, kites_from_config, materials_from_config, schedule_from_config, sweep_lengths
from kitegully.tether.gps import flight_angles, read_track, summarise_flight_angles
from kitegully.tether.plots import plot_observed_flight_angles

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.cfg
crs = snakemake.params.crs
obs = cfg["observed"]
frames = []
for flight, cam_path, op_path in zip(obs["flights"], snakemake.input.camera, snakemake.input.operator):
    angles = flight_angles(read_track(cam_path, crs), read_track(op_path, crs), schedule_from_config(flight, obs["settle_s"]))
    angles.insert(0, "kite", flight["kite"])
    angles.insert(0, "flight", flight["name"])
    frames.append(angles)
    log.info("%s: %d paired fixes, angle %.1f-%.1f°", flight["name"], len(angles), angles["flight_angle_deg"].min(), angles["flight_angle_deg"].max())
fixes = pd.concat(frames, ignore_index=True)
fixes["time"] = fixes["time"].dt.strftime("%Y-%m-%dT%H:%M:%SZ")
write_table(fixes, snakemake.output.fixes, markdown=False)
summary = summarise_flight_angles(fixes)
write_table(summary, snakemake.output.summary)

# Model curves for the flights' winds and line material, with the survey kite.
winds = sorted({f["wind_m_s"] for f in obs["flights"] if "wind_m_s" in f})
simulated = None
if winds:
    material_names = {f["material"] for f in obs["flights"]}
    materials = {k: v for k, v in materials_from_config(cfg).items() if k in material_names}
    simulated = flight_angle_table(
        materials, kites_from_config(cfg)[cfg["simulation_kite"]], winds, sweep_lengths(cfg), atmosphere_from_config(cfg), cfg["segment_length_m"]
    )
plot_observed_flight_angles(summary, simulated, snakemake.output.figure)
