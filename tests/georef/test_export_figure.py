"""The GCP residual map: arrows at a stated exaggeration with a reference arrow, unused GCPs, voids."""

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from PIL import Image

from kitegully.georef.export import residual_figure


def test_residual_figure_draws_used_unused_and_leave_one_out_gcps(tmp_path):
    survey = {f"G{i}": np.array([578600.0 + 100 * i, 4081200.0 + 60 * i, 100.0]) for i in range(5)}
    res = pd.DataFrame({"gcp_id": list(survey), "dx_m": [0.01, -0.02, 0.0, np.nan, 0.03], "dy_m": [0.0, 0.01, 0.02, np.nan, -0.01],
                        "dz_m": [0.05, -0.02, 0.0, np.nan, 0.01], "used": [True, True, True, False, False]})
    loo = res.iloc[:3].assign(dx_m=[0.02, -0.03, 0.01])
    cams = gpd.GeoDataFrame({"x_m": [578650.0, 578900.0], "y_m": [4081250.0, 4081400.0]},
                            geometry=[shapely.Point(578650.0, 4081250.0), shapely.Point(578900.0, 4081400.0)], crs="EPSG:32632")
    residual_figure(res, loo, survey, cams, tmp_path / "gcp.png", None, "test data")
    with Image.open(tmp_path / "gcp.png") as im:
        assert im.size[0] > 1000 and im.size[1] > 800                       # print resolution
    residual_figure(res, loo.iloc[:0], survey, cams, tmp_path / "gcp_fixed.png", 500.0)  # a stated scale, no leave-one-out
    assert (tmp_path / "gcp_fixed.png").stat().st_size > 10_000
