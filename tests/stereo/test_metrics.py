import numpy as np
import pytest

from kitegully import InputError
from kitegully.stereo.metrics import fit_A_vs_M, fit_mae_vs_L, fit_through_origin, mae, mre


def test_mae_mre_constructed():
    M = np.array([1.0, 2.0, 4.0])
    A = np.array([1.5, 1.0, 4.0])
    assert mae(M, A) == pytest.approx((0.5 + 1.0 + 0.0) / 3)
    assert mre(M, A) == pytest.approx((50.0 + 50.0 + 0.0) / 3)


def test_fits_through_origin():
    L = np.array([5.0, 10.0, 20.0, 35.0])
    a, r2 = fit_mae_vs_L(L, 0.03 * L)
    assert a == pytest.approx(0.03) and r2 == pytest.approx(1.0)
    b, r2 = fit_A_vs_M([1.0, 2.0, 3.0], [1.0, 2.0, 4.0])
    assert b == pytest.approx((1 + 4 + 12) / 14)
    assert r2 < 1.0
    # an offset the origin-constrained line cannot explain lowers R²
    s, r2 = fit_through_origin([1.0, 2.0, 3.0], [11.0, 12.0, 13.0])
    assert r2 < 0


def test_bad_inputs():
    with pytest.raises(InputError, match="MRE: a measured value is zero"):
        mre([0.0, 1.0], [0.1, 1.0])
    with pytest.raises(InputError, match=r"MAE: measured and photogrammetric values differ in length \(2 vs 3\)"):
        mae([1, 2], [1, 2, 3])
    with pytest.raises(InputError, match="all x values are zero"):
        fit_through_origin([0, 0], [1, 2])
