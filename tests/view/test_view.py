"""Overlays, timelines and Rerun recordings of an episode."""

import numpy as np
import pytest

from hsp.dataset.features import TrackStatus
from hsp.sim.camera import CameraConfig, look_at_pose
from hsp.sim.render import RgbdRenderer, load_mesh
from hsp.perception.pointcloud import project
from hsp.view.overlay import _mask, draw_frame
from hsp.view.rerun_log import write_rrd
from hsp.view.timeline import bands, write_timeline


def test_a_point_projects_to_the_pinhole_pixel():
    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    uv, z = project(np.array([[0.1, -0.05, 1.0]]), K, np.array([0, 0, 0, 0, 0, 0, 1.0]))
    np.testing.assert_allclose(uv[0], [380.0, 210.0], atol=1e-9)
    assert z[0] == pytest.approx(1.0)


@pytest.fixture(scope="module")
def scene(tasks):
    task = tasks["stacking-1"]
    meshes = [load_mesh(task.mesh(i)) for i in range(len(task.objects))]
    cam = CameraConfig()
    T_world_cam = look_at_pose(np.array([1.2, 0.1, 0.8]), np.array([0.55, 0.0, 0.05]))
    poses = np.array([[0.55, -0.1, 0.25, 0, 0, 0, 1.0], [0.5, 0.0, 0.02, 0, 0, 0.2, 0.98],
                      [0.6, 0.12, 0.02, 0, 0, 0, 1.0], [0.45, -0.15, 0.02, 0, 0, 0.38, 0.925]])
    poses[:, 3:] /= np.linalg.norm(poses[:, 3:], axis=1, keepdims=True)
    rgb, depth, ids = RgbdRenderer(meshes, cam).render(T_world_cam, poses)
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])
    return meshes, poses, rgb, depth, ids, K, T_world_cam


def test_a_vertex_lands_on_the_pixel_the_renderer_sees_it_at(scene):
    """The ray-cast depth at a block's projected top corner is that corner's depth (±1 px)."""
    meshes, poses, rgb, depth, ids, K, T_world_cam = scene
    from hsp.geometry import transform_points

    corners = transform_points(poses[2], meshes[2].vertices)
    top = corners[np.argmax(corners[:, 2] - 0.001 * np.linalg.norm(corners[:, :2] - T_world_cam[:2], axis=1))]
    uv, z = project(top[None], K, T_world_cam)
    u0, v0 = np.round(uv[0]).astype(int)
    window = depth[v0 - 1: v0 + 2, u0 - 1: u0 + 2]
    hit = ids[v0 - 1: v0 + 2, u0 - 1: u0 + 2] == 2
    assert hit.any(), "the renderer sees the block within 1 px of the projected corner"
    assert np.min(np.abs(window[hit] - z[0])) < 0.002


def test_projected_silhouettes_match_the_rendered_ones(scene):
    meshes, poses, rgb, depth, ids, K, T_world_cam = scene
    for i in range(1, 4):
        m = _mask(meshes[i], poses[i], K, T_world_cam, ids.shape) > 0
        visible = ids == i
        assert (m & visible).sum() / visible.sum() > 0.97  # every visible pixel is inside the projection
    img = draw_frame(rgb, meshes, poses, np.array([0, 1, 2, 0]), K, T_world_cam, truth=poses)
    assert img.shape == rgb.shape and not np.array_equal(img[..., ::-1], rgb)


def test_bands_reproduce_the_labels():
    labels = np.array([1, 1, 1, 3, 3, 2, 2, 2, 2, 1])
    b = bands(labels)
    assert b == [(0, 3, 1), (3, 5, 3), (5, 9, 2), (9, 10, 1)]
    np.testing.assert_array_equal(np.concatenate([np.full(e - s, v) for s, e, v in b]), labels)
    assert bands(np.array([])) == []


def test_timeline_png_is_written(tmp_path):
    T = 50
    labels = {"tool": np.r_[np.zeros(20, int), np.ones(30, int)], "target": np.full(T, 2), "waypoint_index": np.r_[np.full(25, 24), np.full(25, 49)]}
    status = np.zeros((T, 3), int)
    status[10:15, 1] = TrackStatus.LOST
    path = write_timeline(tmp_path / "t.png", ["hand", "a", "b"], labels, status, truth=labels, title="x")
    from PIL import Image

    assert Image.open(path).size[0] > 800


def test_rrd_holds_camera_objects_and_labels(scene, tmp_path):
    import rerun.dataframe as rdf

    meshes, poses, rgb, depth, ids, K, T_world_cam = scene
    T = 4
    P = np.repeat(poses[None], T, axis=0)
    labels = {"tool": np.zeros(T, int), "target": np.full(T, 2), "waypoint_index": np.full(T, 3)}
    names = ["hand", "block_blue", "block_green", "block_red"]
    path = write_rrd(tmp_path / "e.rrd", names, meshes, P, np.repeat(rgb[None], T, 0), np.repeat(depth[None], T, 0),
                     K, T_world_cam, labels, truth=P)
    rec = rdf.load_recording(str(path))
    entities = {c.entity_path for c in rec.schema().component_columns()}
    assert {"/world/camera", "/world/camera/rgb", "/world/camera/depth", "/world/objects/block_red",
            "/world/objects/block_red/mesh", "/world/truth/hand", "/labels/target"} <= entities
    table = rec.view(index="frame", contents="/world/objects/block_red").select().read_all()
    assert table.num_rows == T
