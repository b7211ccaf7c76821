"""Figures of the simulated flight: flight map with footprints, and sample photos."""

import numpy as np
import pandas as pd
from matplotlib.collections import PolyCollection
from PIL import Image

from kitegully.io.figures import new_figure, save_figure
from kitegully.logs import setup_script_logging
from kitegully.twin.camera import Camera
from kitegully.twin.flight import pose_from_row, read_extent
from kitegully.twin.flight_gcps import read_odm_gcp_list

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.flight
camera = Camera.read_json(snakemake.input.camera)
poses = pd.read_csv(snakemake.input.poses)
stats = pd.read_csv(snakemake.input.image_stats).set_index("image")
op = pd.read_csv(snakemake.input.operator_track)
survey = pd.read_csv(snakemake.input.survey)
xmin, ymin, xmax, ymax = read_extent(snakemake.input.site)

# footprints: image corners on the plane through the centre ray's ground hit
corners_px = np.array([[-0.5, -0.5], [camera.width - 0.5, -0.5], [camera.width - 0.5, camera.height - 0.5],
                       [-0.5, camera.height - 0.5]])
rays = camera.rays_camera(corners_px[:, 0], corners_px[:, 1])
centre_ray = camera.rays_camera(np.array([camera.cx]), np.array([camera.cy]))[0]
polys = []
for _, p in poses.iterrows():
    pose = pose_from_row(p)
    depth = stats.loc[p["image"], "gsd_m"] * camera.f
    zg = pose.C[2] + depth * (centre_ray @ pose.R)[2]
    d = rays @ pose.R
    t = (zg - pose.C[2]) / d[:, 2]
    polys.append(pose.C[None, :2] + t[:, None] * d[:, :2])

fig, ax = new_figure(figsize=(7.0, 6.0))
ax.add_collection(PolyCollection(polys, facecolors="none", edgecolors="0.55", linewidths=0.4, label="image footprints"))
ax.plot(op["x_m"], op["y_m"], color="tab:brown", lw=0.9, label="operator path")
sc = ax.scatter(poses["x_m"], poses["y_m"], c=poses["z_m"], cmap="viridis", s=14, zorder=3, label="camera positions")
fig.colorbar(sc, ax=ax, label="camera elevation (m)")
ax.plot([xmin, xmax, xmax, xmin, xmin], [ymin, ymin, ymax, ymax, ymin], color="k", lw=1.2, label="twin extent")
ax.scatter(survey["x"], survey["y"], marker="s", s=18, facecolors="white", edgecolors="red", zorder=4, label="GCP targets")
wind = np.radians(cfg["wind_from_deg"] + 180)
ax.annotate("", xy=(xmin + 0.12 * (xmax - xmin) * np.sin(wind) + 0.1 * (xmax - xmin), ymax - 0.1 * (ymax - ymin)
                    + 0.12 * (ymax - ymin) * np.cos(wind)),
            xytext=(xmin + 0.1 * (xmax - xmin), ymax - 0.1 * (ymax - ymin)),
            arrowprops=dict(arrowstyle="->", color="tab:blue", lw=1.5))
ax.text(xmin + 0.1 * (xmax - xmin), ymax - 0.06 * (ymax - ymin), f"wind {cfg['wind_speed_m_s']:g} m/s", color="tab:blue",
        fontsize=7)
ax.set_aspect("equal")
ax.ticklabel_format(useOffset=False, style="plain")
ax.set_xlabel("easting (m)")
ax.set_ylabel("northing (m)")
ax.set_title(f"Simulated kite flight: {len(poses)} images, line {', '.join(f'{v:g}' for v in cfg['line_lengths_m'])} m")
ax.legend(loc="lower left", fontsize=6, framealpha=0.9)
save_figure(fig, snakemake.output.flight_map)

_, obs = read_odm_gcp_list(snakemake.input.gcp_list)
n = min(cfg["figures"]["n_sample_images"], len(poses))
pick = poses["image"].iloc[np.linspace(0, len(poses) - 1, n).round().astype(int)].tolist()
ncol = 2 if n > 1 else 1
nrow = int(np.ceil(n / ncol))
fig, axes = new_figure(nrow, ncol, figsize=(7.0, 7.0 * nrow / ncol * camera.height / camera.width + 0.4), squeeze=False)
for ax, name in zip(axes.ravel(), pick):
    ax.imshow(Image.open(f"{snakemake.input.images}/{name}"))
    o = obs[obs["image"] == name]
    ax.scatter(o["im_x_px"], o["im_y_px"], s=40, facecolors="none", edgecolors="red", lw=0.8)
    for _, r in o.iterrows():
        ax.text(r["im_x_px"] + 15, r["im_y_px"], r["gcp_id"], color="red", fontsize=6)
    row = stats.loc[name]
    ax.set_title(f"{name}: GSD {row['gsd_m'] * 100:.1f} cm, exposure {row['ev_offset']:+.2f} EV", fontsize=7)
    ax.set_xlabel("image x (px)")
    ax.set_ylabel("image y (px)")
    ax.grid(False)
for ax in axes.ravel()[n:]:
    ax.axis("off")
fig.subplots_adjust(hspace=0.4, wspace=0.3)
save_figure(fig, snakemake.output.samples)
