"""What a policy sees of the scene in closed loop.

* ``sim``: the simulator's true poses.
* ``camera``: what the paper's real robot had. Every control step renders colour and
  depth of the scene with the recordings' camera (pose jittered per episode) and depth
  sensor model, and the tracker that built the datasets estimates the poses online, frame
  by frame (:class:`~hsp.perception.tracker.FrameTracker`). The true poses only place the
  meshes in the rendered image; the tracker never reads them. As in the recordings, the
  image shows the task's objects, not the arm. The end effector e_t (object 0) is the one
  pose a robot reads from its own joints rather than the camera: it comes from the arm's
  forward kinematics, as on the paper's Kuka; the tracker still follows its mesh, since it
  occludes and touches the objects. The episode starts once the tracker has found every
  object, or after its first ``LOOK_SEARCHES`` global searches (:meth:`CameraObserver.reset`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from hsp.perception.episode import first_frame_tracker, object_models
from hsp.perception.tracker import TrackerConfig
from hsp.recording.writer import CameraRig
from hsp.sim.camera import sample_camera_pose
from hsp.sim.depth_noise import add_depth_noise
from hsp.sim.render import RgbdRenderer, load_mesh
from hsp.tasks.registry import Task


LOOK_SEARCHES = 3
"""Global searches for objects the first frame missed (after 1, 2 and 4 × ``redetect_after``
still frames) before the episode starts without them."""


class Observer(Protocol):
    def reset(self, true_poses: np.ndarray, seed: int) -> np.ndarray: ...

    def observe(self, true_poses: np.ndarray) -> np.ndarray: ...


class SimObserver:
    """The simulator's world poses ``(n, 7)``, as they are."""

    def reset(self, true_poses: np.ndarray, seed: int) -> np.ndarray:
        return true_poses

    def observe(self, true_poses: np.ndarray) -> np.ndarray:
        return true_poses


class CameraObserver:
    """Poses ``(n, 7)`` tracked online in rendered, noisy RGB-D frames."""

    def __init__(self, task: Task, rig: CameraRig, tracker: TrackerConfig = TrackerConfig(), seed: int = 0) -> None:
        self.task, self.rig, self.cfg = task, rig, tracker
        self.models = object_models(task, tracker, seed)
        self.renderer = RgbdRenderer([load_mesh(task.mesh(i)) for i in range(len(task.objects))], rig.camera)
        self.status = np.zeros(len(task.objects), np.int64)

    def _frame(self, true_poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rgb, depth, _ = self.renderer.render(self.T_world_cam, true_poses)
        return rgb, add_depth_noise(depth, self.rig.camera.fx, self.rig.noise, self.rng).astype(np.float32) / 1000.0

    def reset(self, true_poses: np.ndarray, seed: int) -> np.ndarray:
        """The first frame's estimate, with the still scene looked at again until every object
        is found (a plan made from a nut not yet found sent the wrench to the table's origin)."""
        self.rng = np.random.default_rng([seed, 1])  # camera pose and sensor noise, apart from the layout's stream
        self.T_world_cam = sample_camera_pose(self.rig.camera, self.rng)
        rgb, depth = self._frame(true_poses)
        self.tracker = first_frame_tracker(self.task, rgb, depth, self.rig.camera.K, self.T_world_cam, self.models, self.cfg)
        poses, self.status = self.tracker.update(rgb, depth)
        for _ in range(2 ** (LOOK_SEARCHES - 1) * self.cfg.redetect_after - 1):  # the robot waits, still, for the rest
            if self.tracker.known.all():
                break
            poses, self.status = self.tracker.update(*self._frame(true_poses))
        return self._proprioception(poses, true_poses)

    def observe(self, true_poses: np.ndarray) -> np.ndarray:
        poses, self.status = self.tracker.update(*self._frame(true_poses))
        return self._proprioception(poses, true_poses)

    @staticmethod
    def _proprioception(tracked: np.ndarray, true_poses: np.ndarray) -> np.ndarray:
        """Tracked poses with e_t, object 0, from the arm's forward kinematics."""
        out = tracked.copy()
        out[0] = true_poses[0]
        return out
