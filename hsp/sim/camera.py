"""The RGB-D camera of the recordings: pinhole intrinsics like a RealSense D435 colour
stream and a pose that varies a little between episodes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.errors import HspError


@dataclass(frozen=True)
class CameraConfig:
    width: int = 640
    height: int = 480
    fx: float = 615.0
    """Focal length in pixels (D435 colour at 640×480: about 615)."""
    fy: float = 615.0
    cx: float = 320.0
    """Principal point in pixels, OpenCV convention (pixel centres at integers)."""
    cy: float = 240.0
    eye: tuple[float, float, float] = (1.25, 0.0, 0.9)
    """Nominal camera position in the world (table) frame (m): across the table."""
    look_at: tuple[float, float, float] = (0.57, 0.0, 0.05)
    jitter_m: float = 0.03
    """Per-episode uniform jitter of the position (m)."""
    jitter_deg: float = 2.0
    """Per-episode uniform jitter of the viewing direction (degrees)."""

    def __post_init__(self) -> None:
        if self.width < 8 or self.height < 8:
            raise HspError(f"camera resolution {self.width}x{self.height}: too small")
        if self.fx <= 0 or self.fy <= 0:
            raise HspError(f"camera focal lengths fx={self.fx}, fy={self.fy}: must be positive")

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, width: int, height: int) -> "CameraConfig":
        """The same field of view at another resolution."""
        sx, sy = width / self.width, height / self.height
        return CameraConfig(width, height, self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5,
                            self.eye, self.look_at, self.jitter_m, self.jitter_deg)


def look_at_pose(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``T_world_cam`` (7,) of an optical frame (x right, y down, z forward) at ``eye``
    looking at ``target``, with the image's up roughly along world +z."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-6:
        raise HspError("camera looks straight up or down; move camera.eye")
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return np.concatenate([eye, Rotation.from_matrix(np.stack([x, y, z], axis=1)).as_quat()])


def sample_camera_pose(cfg: CameraConfig, rng: np.random.Generator) -> np.ndarray:
    """The episode's ``T_world_cam``: nominal pose with position and direction jitter."""
    eye = np.asarray(cfg.eye) + rng.uniform(-cfg.jitter_m, cfg.jitter_m, 3)
    T = look_at_pose(eye, np.asarray(cfg.look_at))
    tilt = Rotation.from_rotvec(np.radians(rng.uniform(-cfg.jitter_deg, cfg.jitter_deg, 3)))
    T[3:] = (Rotation.from_quat(T[3:]) * tilt).as_quat()
    return T
