"""Rule tether_plan: flight plan per strip and the line lengths the model needs per material."""

from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.tether.analysis import line_lengths_for_heights
from kitegully.tether.config import atmosphere_from_config, camera_from_config, kites_from_config, materials_from_config
from kitegully.tether.planning import plan_flight

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.cfg
plan_cfg = cfg["plan"]
camera = camera_from_config(plan_cfg["camera"])
plan = plan_flight(
    camera,
    flying_heights_m=plan_cfg["flying_heights_m"],
    worst_flight_angle_deg=plan_cfg["worst_flight_angle_deg"],
    trigger_interval_s=plan_cfg["trigger_interval_s"],
    walking_speed_m_s=plan_cfg["walking_speed_m_s"],
    stereo_min_overlap=plan_cfg["stereo_min_overlap"],
    max_flying_height_m=plan_cfg["max_flying_height_m"],
    target_gsd_m=plan_cfg["target_gsd_m"],
)
write_table(plan, snakemake.output.plan)
for row in plan.itertuples():
    log.info(
        "H %.0f m: line %.0f m, GSD %.3f m, footprint %.0f x %.0f m, overlap %.2f, B/H %.2f, dz %.3f m",
        row.flying_height_m, row.line_length_m, row.gsd_m, row.footprint_across_m, row.footprint_along_m,
        row.forward_overlap, row.base_height_ratio, row.precision_z_m,
    )
lengths = line_lengths_for_heights(
    {k: v for k, v in materials_from_config(cfg).items()},
    kites_from_config(cfg)[cfg["simulation_kite"]],
    cfg["sweep"]["winds_m_s"],
    plan["flying_height_m"].tolist(),
    atmosphere_from_config(cfg),
    plan_cfg["model_max_line_length_m"],
    cfg["segment_length_m"],
)
write_table(lengths, snakemake.output.lengths)
unreachable = lengths[~lengths["reachable"]]
for row in unreachable.itertuples():
    log.warning("%s at %g m/s cannot reach %g m within %g m of line", row.material, row.wind_m_s, row.flying_height_m, plan_cfg["model_max_line_length_m"])
