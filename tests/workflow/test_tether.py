"""The tether stage runs through Snakemake on the tiny site and writes the documented outputs."""

import pandas as pd
import pytest

from snakemake_utils import REPO, run_snakemake

pytestmark = pytest.mark.xdist_group("workflow")


def test_tether_stage_outputs(tmp_path):
    site = REPO / "config" / "sites" / "tiny_twin.yaml"
    out = tmp_path / "results"
    targets = [
        f"{out}/tiny_twin/tether/{name}"
        for name in (
            "flight_angles.csv",
            "line_shapes.png",
            "flight_angle_vs_length.png",
            "table2_comparison.csv",
            "flight_plan.csv",
            "line_lengths_for_heights.csv",
            "observed_flight_angles.csv",
            "observed_flight_angles.png",
        )
    ]
    run_snakemake(site, out, targets=targets, cores=2)
    tether = out / "tiny_twin" / "tether"
    angles = pd.read_csv(tether / "flight_angles.csv")
    assert {"material", "wind_m_s", "line_length_m", "flight_angle_deg", "kite_height_m", "kite_distance_m", "flies"} <= set(angles.columns)
    poly = angles[(angles["material"] == "polyester") & (angles["wind_m_s"] == 3) & (angles["line_length_m"] == 700)]
    assert not poly["flies"].iloc[0] and poly["status"].iloc[0] == "line_on_ground"
    plan = pd.read_csv(tether / "flight_plan.csv")
    assert list(plan.columns[:8]) == [
        "line_length_m", "flying_height_m", "gsd_m", "footprint_across_m", "footprint_along_m",
        "forward_overlap", "base_height_ratio", "precision_z_m",
    ]
    assert (tether / "flight_plan.md").read_text().startswith("|")
    observed = pd.read_csv(tether / "observed_flight_angles.csv")
    assert set(observed["flight"]) == {"F1", "F2"}
    for png in tether.glob("*.png"):
        assert png.stat().st_size > 20_000
    assert (out / "tiny_twin" / "logs" / "tether" / "simulation.log").read_text().count("Table 2 under") == 2
    report = tmp_path / "report.html"
    run_snakemake(site, out, targets=targets, extra=["--report", str(report)])
    html = report.read_text(errors="ignore")
    for name in ("line_shapes.png", "flight_angle_vs_length.png", "observed_flight_angles.png", "flight_plan.csv"):
        assert name in html
