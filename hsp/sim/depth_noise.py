"""A RealSense-like depth sensor model applied to ideal depth images.

Active stereo measures disparity d = f·B / z; its error is roughly constant in disparity
(σ_d ≈ 0.08 px), so the depth error grows with z²: σ_z ≈ z²·σ_d / (f·B), about 0.9 mm at
0.5 m and 3.8 mm at 1 m for a D435 (B = 50 mm). On top: spatially correlated disparity
error, stereo shadows beside foreground edges, dropouts and flying pixels at depth edges,
small holes, range limits, an optional scale bias, and 1 mm quantisation in uint16 mm
(0 = no reading), as the driver publishes ``16UC1`` aligned depth.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from hsp.errors import HspError


@dataclass(frozen=True)
class DepthNoiseConfig:
    enabled: bool = True
    baseline_m: float = 0.05
    """Stereo baseline B (D435: 50 mm; D415: 55 mm)."""
    disparity_sigma_px: float = 0.08
    """White disparity noise σ_d (px)."""
    correlated_sigma_px: float = 0.04
    """Disparity noise correlated over ``correlated_cell_px`` blocks (px)."""
    correlated_cell_px: int = 8
    edge_jump_m: float = 0.02
    """A depth step larger than this makes an edge pixel."""
    edge_dropout: float = 0.5
    """Fraction of edge pixels without a reading."""
    edge_flying: float = 0.15
    """Fraction of edge pixels mixing foreground and background depth."""
    hole_fraction: float = 0.02
    """Fraction of the image lost in small blobs (textureless or specular patches)."""
    min_range_m: float = 0.2
    max_range_m: float = 4.0
    scale_bias: float = 0.0
    """Relative depth-scale error (RealSense units show 1–2 %); off by default."""

    def __post_init__(self) -> None:
        for key in ("edge_dropout", "edge_flying", "hole_fraction"):
            if not 0.0 <= getattr(self, key) <= 1.0:
                raise HspError(f"depth_noise.{key} = {getattr(self, key)}: must be in [0, 1]")
        if self.min_range_m >= self.max_range_m:
            raise HspError(f"depth_noise.min_range_m {self.min_range_m} >= max_range_m {self.max_range_m}")


def _edges(z: np.ndarray, zmax: np.ndarray, jump: float) -> np.ndarray:
    """Pixels next to a depth step larger than ``jump`` (or next to no return); ``zmax``
    is the 3×3 maximum of ``z``."""
    zmin = cv2.erode(np.where(z > 0, z, np.float32(1e6)).astype(np.float32), np.ones((3, 3), np.uint8))
    return (zmax - zmin) > jump


def _shadow(z: np.ndarray, fb: float, step: int = 3, max_shift: int = 45) -> np.ndarray:
    """Background pixels hidden from the second imager by a foreground object to their
    right (the emitter/imager sit to one side): pixel u is shadowed when some pixel u + k
    is nearer by enough that its disparity covers the gap, k < f·B·(1/z_near − 1/z)."""
    inv = np.where(z > 0, 1.0 / np.maximum(z, 1e-6), 0.0).astype(np.float32)
    shadow = np.zeros(z.shape, bool)
    for k in range(step, max_shift + 1, step):
        near = np.zeros_like(inv)
        near[:, :-k] = inv[:, k:]
        shadow |= (near - inv) * fb > k
    return shadow & (z > 0)


def add_depth_noise(depth_m: np.ndarray, fx: float, cfg: DepthNoiseConfig, rng: np.random.Generator) -> np.ndarray:
    """Noisy depth in uint16 millimetres (0 = no reading) from ideal depth ``(H, W)`` m."""
    z = depth_m.astype(np.float32)
    valid = z > 0
    if not cfg.enabled:
        out = np.where(valid, np.round(z * 1000.0), 0)
        return np.clip(out, 0, 65535).astype(np.uint16)
    H, W = z.shape
    fb = np.float32(fx * cfg.baseline_m)
    disparity = np.where(valid, fb / np.maximum(z, 1e-6), 0).astype(np.float32)
    disparity += rng.standard_normal((H, W), dtype=np.float32) * np.float32(cfg.disparity_sigma_px)
    c = cfg.correlated_cell_px
    coarse = rng.normal(0.0, cfg.correlated_sigma_px, (H // c + 1, W // c + 1)).astype(np.float32)
    disparity += cv2.resize(coarse, (W // c * c + c, H // c * c + c), interpolation=cv2.INTER_LINEAR)[:H, :W]
    noisy = np.where(valid, fb / np.maximum(disparity, 1e-3), 0).astype(np.float32)

    zmax = cv2.dilate(z, np.ones((3, 3), np.uint8))
    edges = _edges(z, zmax, cfg.edge_jump_m)
    u = rng.random((H, W), dtype=np.float32)
    drop = edges & (u < cfg.edge_dropout)
    flying = edges & (u >= cfg.edge_dropout) & (u < cfg.edge_dropout + cfg.edge_flying)
    mix = (u - np.float32(cfg.edge_dropout)) / np.float32(max(cfg.edge_flying, 1e-6))  # uniform on flying pixels
    noisy = np.where(flying, noisy * mix + zmax * (1 - mix), noisy)

    holes = cv2.resize((rng.random((H // 4, W // 4)) < cfg.hole_fraction).astype(np.uint8), (W, H),
                       interpolation=cv2.INTER_NEAREST).astype(bool)
    lost = drop | holes | _shadow(z, fb) | ~valid
    noisy *= np.float32(1.0 + cfg.scale_bias)
    lost |= (noisy < cfg.min_range_m) | (noisy > cfg.max_range_m)
    mm = np.round(noisy * 1000.0)
    mm[lost] = 0
    return np.clip(mm, 0, 65535).astype(np.uint16)
