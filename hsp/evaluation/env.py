"""A gymnasium environment per task: the simulated Kuka holding the task's tool.

``reset(seed)`` draws a layout with the task's own sampler (as every demonstration did);
``step(action)`` takes an end-effector (tool-centre point, object 0) pose command and a
grip command and advances physics for one control period of the recordings. The
observation is laid out as the dataset's ``observation.state`` (``agent_pos``, e_t) and
``observation.environment_state`` (``environment_state``: the other objects' world poses,
flattened), LeRobot's keys for its gym environments; ``info["is_success"]`` and the
per-sub-goal ``info["progress"]`` come from the task's success criterion.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pybullet as p

from hsp.errors import HspError
from hsp.geometry import inverse, normalize_quat, rotation_angle_deg, slerp, transform_points
from hsp.evaluation.observers import Observer, SimObserver
from hsp.geometry.mesh import obj_vertices
from hsp.sim.scene import SIM_HZ, Scene
from hsp.tasks.layout import sample_layout
from hsp.tasks.registry import Task
from hsp.tasks.success import progress

SETTLE_S = 0.25
"""Physics time after a reset, the arm holding its pose, before the first observation."""
GRIP_CLOSED = -1
"""Grip command of a policy that knows no objects (a gripper closing on what it touches)."""


@dataclass(frozen=True)
class EnvConfig:
    fps: int = 15
    """Control rate (Hz): that of the recordings (``record.fps``)."""
    max_steps: int = 600
    """Control steps before the episode is truncated (about twice the longest demonstration)."""
    grasp_reach_m: float = 0.01
    """The gripper closes on an object when the tool-centre point is within this of the
    object's bounding box (m)."""
    max_speed_m_s: float = 1.0
    """The controller moves the tool-centre point at most this fast (m/s) toward a command
    (twice the demonstrators' peak speed); farther commands are approached over several steps."""
    max_turn_deg_s: float = 180.0
    """... and turns it at most this fast (degrees/s)."""

    def __post_init__(self) -> None:
        if self.fps < 1 or SIM_HZ % self.fps:
            raise HspError(f"eval fps = {self.fps}: must divide the simulation rate {SIM_HZ} Hz")
        if self.max_steps < 1:
            raise HspError(f"eval.max_steps = {self.max_steps}: must be at least 1")
        if self.grasp_reach_m < 0:
            raise HspError(f"eval.grasp_reach_m = {self.grasp_reach_m}: must be ≥ 0")
        if self.max_speed_m_s <= 0 or self.max_turn_deg_s <= 0:
            raise HspError(f"eval.max_speed_m_s = {self.max_speed_m_s}, eval.max_turn_deg_s = {self.max_turn_deg_s}: must be > 0")


def observation(poses: np.ndarray) -> dict[str, np.ndarray]:
    """World poses ``(n, 7)`` laid out as the dataset: e_t ``(7,)`` and the others ``(7(n−1),)``."""
    return {"agent_pos": poses[0].astype(np.float32), "environment_state": poses[1:].reshape(-1).astype(np.float32)}


def world_poses(obs: dict[str, np.ndarray]) -> np.ndarray:
    """The inverse of :func:`observation`: world poses ``(n, 7)`` as float64."""
    return np.concatenate([obs["agent_pos"][None], obs["environment_state"].reshape(-1, 7)]).astype(np.float64)


class HspEnv(gym.Env):
    """One task on the Kuka, seen through an observer (default: the simulator's poses;
    :mod:`~hsp.evaluation.observers`). Action ``(8,)``: the tool-centre point's world pose
    ``[x, y, z, qx, qy, qz, qw]`` at the end of the step, then the object to hold (0: none;
    ``i``: close on object ``i`` once it is within grasp reach; :data:`GRIP_CLOSED`: close
    on the nearest object within grasp reach, as a plain gripper does; it is let go when the
    command returns to 0). Either closes as soon as its object comes within reach while the
    command stays closed (one closed on air does not have to open first), the same for
    every method. The arm moves there along a straight line and a slerp over the step."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    def __init__(self, task: Task, config: EnvConfig = EnvConfig(), render_mode: str | None = None,
                 observer: Observer | None = None) -> None:
        self.task, self.config, self.render_mode = task, config, render_mode
        self.observer: Observer = observer or SimObserver()
        self.metadata = {**self.metadata, "render_fps": config.fps}
        n = len(task.objects)
        self.observation_space = gym.spaces.Dict({
            "agent_pos": gym.spaces.Box(-np.inf, np.inf, (7,), np.float32),
            "environment_state": gym.spaces.Box(-np.inf, np.inf, (7 * (n - 1),), np.float32),
        })
        low = np.array([-2, -2, -1, -1, -1, -1, -1, GRIP_CLOSED], np.float32)
        high = np.array([2, 2, 2, 1, 1, 1, 1, n - 1], np.float32)
        self.action_space = gym.spaces.Box(low, high, dtype=np.float32)
        verts = [obj_vertices(task.mesh(i)) for i in range(n)]
        self._box_lo, self._box_hi = np.array([v.min(0) for v in verts]), np.array([v.max(0) for v in verts])
        self.scene: Scene | None = None
        self.poses: list[np.ndarray] = []

    # -- gymnasium API ---------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        self.close()
        layout = sample_layout(self.task, self.np_random)
        self.scene = Scene(self.task, layout, "kuka")
        self._command = self.scene.ee.tcp_pose()
        for _ in range(round(SETTLE_S * SIM_HZ)):
            self.scene.substep(self._command)
        self.held = 0
        self.steps = 0
        self.poses = [self.scene.object_poses()]
        seen = self.observer.reset(self.poses[-1], seed if seed is not None else int(self.np_random.integers(2**31)))
        return observation(seen), self._info()

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        if self.scene is None:
            raise RuntimeError("call reset() before step()")
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (8,) or not np.all(np.isfinite(action)):
            raise HspError(f"action must be 8 finite numbers (pose, object to hold), got {action!r}")
        goal = self._limited(np.concatenate([action[:3], normalize_quat(action[3:7])]))
        self._grip(int(round(action[7])))
        substeps = SIM_HZ // self.config.fps
        s = np.arange(1, substeps + 1) / substeps
        path = np.concatenate([self._command[:3] + s[:, None] * (goal[:3] - self._command[:3]),
                               slerp(self._command[3:], goal[3:], s)], axis=1)
        for T in path:
            self.scene.substep(T)
        self._command = goal
        self.steps += 1
        self.poses.append(self.scene.object_poses())
        info = self._info()
        terminated = info["is_success"]
        truncated = not terminated and self.steps >= self.config.max_steps
        return observation(self.observer.observe(self.poses[-1])), float(terminated), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """An RGB frame (PyBullet's TinyRenderer, 320×240, the arm included) from across the table."""
        if self.render_mode != "rgb_array" or self.scene is None:
            return None
        c = self.scene.client
        view = p.computeViewMatrix([1.3, -0.8, 0.75], [0.5, 0.0, 0.1], [0, 0, 1], physicsClientId=c)
        proj = p.computeProjectionMatrixFOV(45, 320 / 240, 0.05, 5.0, physicsClientId=c)
        rgba = p.getCameraImage(320, 240, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=c)[2]
        return np.asarray(rgba, np.uint8).reshape(240, 320, 4)[..., :3]

    def close(self) -> None:
        if self.scene is not None:
            self.scene.close()
            self.scene = None

    # -- helpers ---------------------------------------------------------------------
    def reach_error(self, T_world_tcp: np.ndarray) -> float:
        """How far (m) the arm's IK solution falls short of a tool-centre-point pose."""
        if self.scene is None:
            raise RuntimeError("call reset() before reach_error()")
        return self.scene.ee.reach_error(T_world_tcp)  # type: ignore[union-attr]

    def box_distances(self) -> np.ndarray:
        """Distance (m) from the tool-centre point to each object's box ``(n,)`` (object 0: inf)."""
        poses = self.poses[-1]
        local = transform_points(inverse(poses), poses[0, :3])  # (n, 3): the point in each object's frame
        out = np.linalg.norm(np.maximum(self._box_lo - local, 0) + np.maximum(local - self._box_hi, 0), axis=1)
        out[0] = np.inf
        return out

    def within_reach(self, i: int) -> bool:
        """Whether the tool-centre point is within grasp reach of object ``i``'s box."""
        return bool(self.box_distances()[i] <= self.config.grasp_reach_m)

    def _limited(self, goal: np.ndarray) -> np.ndarray:
        """``goal (7,)`` moved back toward the last command to respect the speed limits."""
        cfg, last = self.config, self._command
        move = goal[:3] - last[:3]
        dist = float(np.linalg.norm(move))
        max_move = cfg.max_speed_m_s / cfg.fps
        pos = last[:3] + move * min(1.0, max_move / dist) if dist > 0 else goal[:3]
        turn = float(rotation_angle_deg(last[3:], goal[3:]))
        max_turn = cfg.max_turn_deg_s / cfg.fps
        quat = slerp(last[3:], goal[3:], np.array([max_turn / turn]))[0] if turn > max_turn else goal[3:]
        return np.concatenate([pos, quat])

    def _grip(self, obj: int) -> None:
        n = len(self.task.objects)
        if not GRIP_CLOSED <= obj < n:
            raise HspError(f"grip command {obj}: not an object index of task {self.task.name!r} (0–{n - 1}) "
                           f"nor {GRIP_CLOSED} (close on the nearest)")
        if obj == GRIP_CLOSED:
            obj = self.held or int(np.argmin(self.box_distances()))
        if obj == self.held:
            return
        if self.held:
            self.scene.release()  # type: ignore[union-attr]
            self.held = 0
        if obj and self.within_reach(obj):
            self.scene.grasp(obj)  # type: ignore[union-attr]
            self.held = obj

    def _info(self) -> dict:
        goals = progress(self.task, np.stack(self.poses), self.held)
        return {"is_success": all(goals.values()), "progress": goals, "held": self.held, "steps": self.steps}
