"""The depth sensor model behaves like a RealSense: σ ∝ z², mm quantisation, edge effects."""

import numpy as np
import pytest

from hsp.errors import HspError
from hsp.sim.depth_noise import DepthNoiseConfig, add_depth_noise

FX = 615.0


def _noise_std_mm(z: float, cfg: DepthNoiseConfig) -> float:
    depth = np.full((240, 320), z, np.float32)
    mm = add_depth_noise(depth, FX, cfg, np.random.default_rng(0)).astype(float)
    return float(np.std(mm[mm > 0] - z * 1000))


def test_axial_noise_grows_with_depth_squared():
    cfg = DepthNoiseConfig(hole_fraction=0.0)
    s05, s10 = _noise_std_mm(0.5, cfg), _noise_std_mm(1.0, cfg)
    assert 0.5 < s05 < 1.5 and 2.0 < s10 < 4.5, (s05, s10)  # D435: ~0.9 and ~3.8 mm
    assert 3.0 < s10 / s05 < 5.5


def test_noise_off_is_exact_quantisation_to_millimetres():
    depth = np.array([[0.5004, 0.0], [1.2346, 2.0]], np.float32)
    out = add_depth_noise(depth, FX, DepthNoiseConfig(enabled=False), np.random.default_rng(0))
    np.testing.assert_array_equal(out, [[500, 0], [1235, 2000]])
    assert out.dtype == np.uint16


def test_edges_lose_readings_and_range_limits_apply():
    depth = np.full((120, 160), 1.0, np.float32)
    depth[40:80, 60:100] = 0.6  # a box in front
    depth[:, :5] = 5.0  # beyond max range
    cfg = DepthNoiseConfig(hole_fraction=0.0)
    out = add_depth_noise(depth, FX, cfg, np.random.default_rng(1))
    assert np.all(out[:, :4] == 0)
    edge_band = np.zeros_like(depth, bool)
    edge_band[39:41, 60:100] = edge_band[79:81, 60:100] = True
    assert (out[edge_band] == 0).mean() > 0.3
    shadow = out[45:75, 40:58]  # left of the box: hidden from the second imager
    assert (shadow == 0).mean() > 0.5
    assert (out[5:30, 120:155] == 0).mean() < 0.05


def test_same_seed_same_noise():
    depth = np.full((60, 80), 0.9, np.float32)
    a = add_depth_noise(depth, FX, DepthNoiseConfig(), np.random.default_rng(5))
    b = add_depth_noise(depth, FX, DepthNoiseConfig(), np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)


def test_bad_config_is_named():
    with pytest.raises(HspError, match="depth_noise.edge_dropout = 1.5"):
        DepthNoiseConfig(edge_dropout=1.5)
