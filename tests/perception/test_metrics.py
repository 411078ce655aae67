import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsp.perception.metrics import add_s, auc, rotation_error_deg, status_trust


def test_rotation_error_respects_symmetry():
    q = Rotation.from_euler("z", 0.3).as_quat()
    q90 = (Rotation.from_euler("z", 0.3 + np.pi / 2)).as_quat()
    assert rotation_error_deg(q90, q, "z_4fold") == pytest.approx(0.0, abs=1e-5)
    assert rotation_error_deg(q90, q, "none") == pytest.approx(90.0, abs=1e-5)
    assert rotation_error_deg(q90, q, "z_continuous") == pytest.approx(0.0, abs=1e-5)
    tilted = (Rotation.from_euler("x", 0.1) * Rotation.from_quat(q)).as_quat()
    assert rotation_error_deg(tilted, q, "z_continuous") == pytest.approx(np.degrees(0.1), abs=1e-4)
    flipped = (Rotation.from_quat(q) * Rotation.from_euler("x", np.pi / 2)).as_quat()
    assert rotation_error_deg(flipped, q, "cube") == pytest.approx(0.0, abs=1e-5)


def test_add_s_of_a_known_shift_and_auc():
    pts = np.random.default_rng(0).normal(size=(200, 3)) * 0.02
    gt = np.array([[0.5, 0, 0.1, 0, 0, 0, 1.0]])
    est = gt.copy()
    est[0, 0] += 0.003
    assert add_s(pts, gt, gt)[0] == pytest.approx(0.0)
    assert 0.0 < add_s(pts, est, gt)[0] <= 0.003 + 1e-12
    assert auc(np.zeros(10)) == pytest.approx(100.0, abs=0.1)
    assert auc(np.full(10, 0.05)) == pytest.approx(50.0, abs=0.2)
    assert auc(np.full(10, 0.2)) == 0.0


def test_status_trust_counts_ok_accuracy_and_flagged_errors():
    te = np.array([1.0, 2.0, 50.0, 3.0, 30.0, 1.0])
    re = np.array([0.5, 9.0, 1.0, 1.0, 1.0, 0.1])  # the second is 9° off: inaccurate
    ok = np.array([True, True, True, False, False, True])
    precision, flagged = status_trust(te, re, ok)
    assert precision == 2 / 4  # ok: 0, 1, 2, 5; accurate among them: 0, 5
    assert flagged == 1 / 3  # inaccurate: 1, 2, 4; not ok among them: 4
    assert np.isnan(status_trust(te[:1], re[:1], ok[:1])[1])  # nothing inaccurate
