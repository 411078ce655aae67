"""Rendering: pinhole geometry is exact, the fast path equals casting every ray."""

import numpy as np
import open3d as o3d

from hsp.geometry import inverse, pose_to_matrix, transform_points
from hsp.sim.camera import CameraConfig, look_at_pose, sample_camera_pose
from hsp.sim.render import RgbdRenderer, load_mesh
from hsp.tasks.layout import sample_layout

CAM = CameraConfig().scaled(160, 120)


def _renderer(task):
    return RgbdRenderer([load_mesh(task.mesh(i)) for i in range(len(task.objects))], CAM)


def test_table_depth_on_the_optical_axis_is_exact(tasks):
    """Looking straight at the table from 1 m along a tilted axis: depth = distance to z = 0."""
    task = tasks["stacking-1"]
    r = RgbdRenderer([load_mesh(task.mesh(i)) for i in range(len(task.objects))],
                     CameraConfig(width=160, height=120, fx=150.0, fy=150.0, cx=80.0, cy=60.0))
    T = look_at_pose(np.array([0.0, 0.8, 0.6]), np.array([0.0, 0.0, 0.0]))
    far_away = np.tile([10.0, 10.0, 0.5, 0, 0, 0, 1.0], (len(r.meshes), 1))
    _, depth, oid = r.render(T, far_away)
    assert abs(depth[60, 80] - 1.0) < 1e-4 and oid[60, 80] == -1


def test_mesh_vertex_lands_on_its_projected_pixel(tasks):
    """The top centre of a block projects to the pixel where the block is seen at that depth."""
    task = tasks["stacking-1"]
    r = _renderer(task)
    poses = sample_layout(task, np.random.default_rng(0))
    T = sample_camera_pose(CAM, np.random.default_rng(1))
    _, depth, oid = r.render(T, poses)
    i = task.index("block_red")
    top = transform_points(poses[i], np.array([0.0, 0.0, 0.02]))
    pc = transform_points(inverse(T), top)
    u = CAM.fx * pc[0] / pc[2] + CAM.cx
    v = CAM.fy * pc[1] / pc[2] + CAM.cy
    assert oid[int(round(v)), int(round(u))] == i
    assert abs(depth[int(round(v)), int(round(u))] - pc[2]) < 0.01


def test_fast_path_equals_casting_every_ray(tasks):
    task = tasks["painting"]
    r = _renderer(task)
    poses = sample_layout(task, np.random.default_rng(3))
    T = sample_camera_pose(CAM, np.random.default_rng(4))
    _, depth, oid = r.render(T, poses)

    scene = o3d.t.geometry.RaycastingScene()
    for m, M in zip(r.meshes, pose_to_matrix(poses)):
        scene.add_triangles(o3d.core.Tensor((m.vertices @ M[:3, :3].T + M[:3, 3]).astype(np.float32)),
                            o3d.core.Tensor(m.triangles))
    M = pose_to_matrix(T)
    u, v = np.meshgrid(np.arange(CAM.width), np.arange(CAM.height))
    d = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones_like(u, float)], -1) @ M[:3, :3].T
    rays = np.concatenate([np.broadcast_to(M[:3, 3], d.shape), d], -1).astype(np.float32)
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    on_object = oid >= 0
    assert on_object.sum() > 100
    np.testing.assert_allclose(depth[on_object], t[on_object], atol=1e-4)
    assert np.all(~np.isfinite(t[~on_object]) | (t[~on_object] >= depth[~on_object] - 1e-4))
