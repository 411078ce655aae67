"""The table frame: from /tf_static when the depth agrees, else fitted to the depth."""

import numpy as np
import pytest

from hsp.errors import HspError
from hsp.geometry import compose, inverse, pose_from_matrix, transform_points
from hsp.perception.table import TableConfig, fit_table, table_frame
from hsp.sim.camera import CameraConfig

CAM = CameraConfig().scaled(160, 120)


def look_at(eye, target) -> np.ndarray:
    """``T_world_cam`` of an optical frame (z forward, y down) at ``eye`` looking at ``target``."""
    z = np.subtract(target, eye) / np.linalg.norm(np.subtract(target, eye))
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    M = np.eye(4)
    M[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    M[:3, 3] = eye
    return pose_from_matrix(M)


def table_depth(T_world_cam: np.ndarray) -> np.ndarray:
    """Depth (m) of the plane z = 0 seen from ``T_world_cam``, with the top of a 10 cm box
    standing on it at (0.5, 0)."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width]
    rays = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones(u.shape)], axis=-1)  # depth 1 along the axis
    eye = T_world_cam[:3]
    dirs = transform_points(np.r_[0.0, 0.0, 0.0, T_world_cam[3:]], rays)
    s = -eye[2] / dirs[..., 2]
    top = (0.1 - eye[2]) / dirs[..., 2]
    on_top = np.all(np.abs(eye[:2] + top[..., None] * dirs[..., :2] - [0.5, 0.0]) < 0.05, axis=-1)
    s = np.where(on_top, top, s)
    return np.where(s > 0, s, 0.0).astype(np.float32)


EYE = look_at([0.0, -0.3, 0.8], [0.5, 0.0, 0.0])


def test_fitted_frame_puts_the_table_at_z0_facing_up():
    depth = table_depth(EYE)
    T, how = table_frame(depth, CAM.K, None, "", None)
    assert how == "fitted"
    v, u = np.nonzero(depth > 0)
    z = depth[v, u]
    pts = np.stack([(u - CAM.cx) / CAM.fx * z, (v - CAM.cy) / CAM.fy * z, z], axis=1)
    heights = transform_points(T, pts)[:, 2]
    assert np.mean(np.abs(heights) < 1e-3) > 0.8  # the table
    assert np.abs(np.percentile(heights, 99) - 0.1) < 2e-3  # the box top stands 10 cm up
    world_from_fitted = compose(EYE, inverse(T))  # a turn about z and a shift on the table, nothing else
    assert np.abs(world_from_fitted[2]) < 1e-3 and np.linalg.norm(world_from_fitted[3:5]) < 1e-3


def test_tf_static_is_used_only_where_the_depth_agrees():
    depth = table_depth(EYE)
    T, how = table_frame(depth, CAM.K, EYE, "world", None)
    assert how == "tf_static world" and np.array_equal(T, EYE)
    # the RealSense driver's chain: camera_link -> ... -> optical frame, no table
    driver = np.array([0.0, 0.015, 0.0, -0.5, 0.5, -0.5, 0.5])
    T, how = table_frame(depth, CAM.K, driver, "camera_link", None)
    assert how == "fitted"
    lifted = EYE + np.r_[0, 0, 0.05, 0, 0, 0, 0]  # 5 cm off: not the table's frame either
    assert table_frame(depth, CAM.K, lifted, "world", None)[1] == "fitted"


def test_a_given_camera_pose_wins():
    T, how = table_frame(table_depth(EYE), CAM.K, None, "", EYE)
    assert how == "given" and np.allclose(T, EYE)


def test_no_table_is_a_one_line_error():
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 2.0, (CAM.height, CAM.width)).astype(np.float32)
    with pytest.raises(HspError, match=r"ep.mcap: no table in the first frames .*--camera-pose"):
        fit_table(depth, CAM.K, TableConfig(), 0, "ep.mcap")


def test_a_bad_first_frame_does_not_decide_the_table():
    """The plane is fitted in the median of the first frames: a first frame of noise (auto-
    exposure settling, a hand across the view) and holes in the others change nothing."""
    rng = np.random.default_rng(1)
    depth = np.repeat(table_depth(EYE)[None], 5, axis=0)
    depth[0] = rng.uniform(0.3, 2.0, depth[0].shape)
    depth[1:][rng.random(depth[1:].shape) < 0.3] = 0.0
    T, how = table_frame(depth, CAM.K, EYE, "world", None)
    assert how == "tf_static world"
    with pytest.raises(HspError, match="no table"):
        table_frame(depth[:1], CAM.K, EYE, "world", None)
