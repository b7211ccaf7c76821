"""Rule flight_figures: flight map with image footprints, and sample photos with their GCPs."""

import pandas as pd

from kitegully.io.figures import save_figure
from kitegully.logs import setup_script_logging
from kitegully.twin.camera import Camera
from kitegully.twin.flight import read_extent
from kitegully.twin.flight_gcps import read_odm_gcp_list
from kitegully.twin import flight_map, sample_images

log = setup_script_logging(snakemake.log[0])
inp, cfg = snakemake.input, snakemake.params.flight
camera = Camera.read_json(inp.camera)
poses = pd.read_csv(inp.poses)
stats = pd.read_csv(inp.image_stats).set_index("image")
fig = flight_map(camera, poses, stats, pd.read_csv(inp.operator_track), pd.read_csv(inp.survey),
                 read_extent(inp.site), cfg)
save_figure(fig, snakemake.output.flight_map)
_, obs = read_odm_gcp_list(inp.gcp_list)
fig = sample_images(camera, poses, stats, obs, inp.images, cfg["figures"]["n_sample_images"])
save_figure(fig, snakemake.output.samples)
