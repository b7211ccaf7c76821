"""The rain runs' process models: settlement, WEPP interrill and flow detachment."""

import numpy as np
import pytest

from kitegully.stereo.erosion import interrill_rate_kg_m2_h, runoff_detachment_kg_m2_h, settlement_mm


def test_runoff_detachment_grows_downslope_above_the_threshold():
    y = np.array([0.0, 0.25, 0.5])
    tau, D = runoff_detachment_kg_m2_h(y, 60.0, 2.41, 10.0, 0.03, 0.0069, 3.5)
    # q = 57.59 mm/h · 0.5 m = 8.0e-6 m²/s; h = (0.03 q / √sin10°)^0.6 = 0.18 mm; τ = ρ g h sin10° = 0.31 Pa
    assert tau[2] == pytest.approx(1000 * 9.81 * (0.03 * 57.59e-3 / 3600 * 0.5 / np.sqrt(np.sin(np.radians(10)))) ** 0.6
                                   * np.sin(np.radians(10)), rel=1e-9)
    assert tau[2] == pytest.approx(0.307, abs=0.005) and (D == 0).all()
    _, D0 = runoff_detachment_kg_m2_h(y, 60.0, 2.41, 10.0, 0.03, 0.0069, 0.0)
    assert D0[0] == 0 and D0[1] < D0[2]  # no threshold: erosion grows with the runoff, downstream more
    _, Dn = runoff_detachment_kg_m2_h(y, 2.0, 2.41, 10.0, 0.03, 0.0069, 0.0)
    assert (Dn == 0).all()  # Ksat > I: no runoff


def test_settlement_and_interrill_maths():
    assert settlement_mm(0.91, 10.0, 1.20) == pytest.approx(10 * (1 - 0.91 / 1.2))
    assert settlement_mm(1.25, 10.0, 1.20) == 0.0
    # WEPP: D_i = K_i I^2 S_f, I = 60 mm/h, 10 deg: S_f = 1.05 - 0.85 exp(-4 sin 10°) = 0.6256
    Sf = 1.05 - 0.85 * np.exp(-4 * np.sin(np.radians(10)))
    assert interrill_rate_kg_m2_h(1e6, 60.0, 10.0) == pytest.approx(1e6 * (60e-3 / 3600) ** 2 * Sf * 3600)
    assert interrill_rate_kg_m2_h(1e6, 60.0, 10.0) == pytest.approx(0.626, abs=0.001)
