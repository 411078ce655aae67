"""Crease edges of a mesh, and a resting object's heading and position found on them."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsp.perception.edges import crease_edges, edge_scores, image_gradient, refine_on_edges
from hsp.geometry import pose_to_matrix
from hsp.sim.camera import CameraConfig, look_at_pose
from hsp.sim.render import RgbdRenderer, load_mesh


def _heading_deg(q, q_true, period_deg):
    turn = np.degrees((Rotation.from_quat(q) * Rotation.from_quat(q_true).inv()).as_euler("xyz")[2])
    return (turn + period_deg / 2) % period_deg - period_deg / 2


def test_a_hex_nut_has_the_creases_of_a_prism_and_of_its_paint_mark(tasks):
    mesh = load_mesh(tasks["tire-removal"].mesh(2))
    creases = crease_edges(mesh)
    assert len(creases.ends) == 18 + 12  # hexagonal prism + box
    cos = np.sum(creases.normals[:, 0] * creases.normals[:, 1], axis=1)
    assert np.all(cos < np.cos(np.radians(20)))
    assert len(crease_edges(mesh, min_deg=100.0).ends) == 0  # no faces meet that sharply


@pytest.fixture(scope="module")
def nut_image(tasks):
    """A rendered hex nut on the table, its true pose, creases and the camera."""
    task = tasks["tire-removal"]
    mesh = load_mesh(task.mesh(2))
    cam = CameraConfig()
    T_world_cam = look_at_pose(np.array(cam.eye), np.array(cam.look_at))
    pose = np.concatenate([[0.55, 0.04, 0.01], Rotation.from_euler("z", 0.3).as_quat()])
    rgb = RgbdRenderer([mesh], cam).render(T_world_cam, pose[None])[0]
    return image_gradient(rgb), crease_edges(mesh), pose, cam.K, T_world_cam


def test_the_edge_score_peaks_at_the_true_pose(nut_image):
    gradient, creases, pose, K, T_world_cam = nut_image
    turns = np.radians(np.arange(-25, 26, 5))
    M = pose_to_matrix(pose)
    candidates = np.repeat(M[None], len(turns), axis=0)
    candidates[:, :3, :3] = Rotation.from_euler("z", turns[:, None]).as_matrix() @ M[:3, :3]
    scores = edge_scores(gradient, creases, candidates, K, T_world_cam)
    assert np.argmax(scores) == len(turns) // 2


@pytest.mark.parametrize("turn_deg, shift_mm", [(8.0, (2.0, -1.5)), (-20.0, (0.0, 3.0)), (27.0, (-4.0, 1.0))])
def test_a_nut_is_turned_and_moved_back_onto_its_edges(nut_image, turn_deg, shift_mm):
    gradient, creases, pose, K, T_world_cam = nut_image
    start = pose.copy()
    start[:2] += np.array(shift_mm) / 1000
    start[3:] = (Rotation.from_euler("z", np.radians(turn_deg)) * Rotation.from_quat(pose[3:])).as_quat()
    found = refine_on_edges(gradient, creases, start, np.radians(60.0), K, T_world_cam)
    # A 16-pixel-wide nut's edges sit on whole pixels: half a pixel is 3° at its corners
    assert abs(_heading_deg(found[3:], pose[3:], 60.0)) < 3.0
    assert np.linalg.norm(found[:2] - pose[:2]) < 0.001
    assert found[2] == start[2]  # only the heading and the horizontal position are searched


def test_without_edge_evidence_the_pose_stays_where_it_is(nut_image):
    """A blank image (or a mesh without creases) scores every candidate 0: no grid corner
    may win by being first."""
    gradient, creases, pose, K, T_world_cam = nut_image
    blank = np.zeros_like(gradient)
    assert np.allclose(refine_on_edges(blank, creases, pose, np.radians(60.0), K, T_world_cam), pose)
