"""Running a scripted demonstrator in a scene and recording what happened.

Every frame stores the world pose of every object and the demonstrator's own sub-task
annotation (tool o+, target o*, way-point w in the target frame): the ground truth that
only evaluation and the supervised variant may read.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from hsp.errors import HspError
from hsp.geometry import compose, inverse, relative, rotation_angle_deg
from hsp.sim.demonstrators import PLANS
from hsp.sim.demonstrators.steps import Grasp, Move, Release, Step
from hsp.sim.motion import Tremor, segment_poses
from hsp.sim.scene import SIM_HZ, Scene
from hsp.tasks.layout import sample_layout
from hsp.tasks.registry import Task
from hsp.tasks.success import is_success


@dataclass
class Demonstration:
    """One recorded episode; ``T`` frames at ``fps``, ``n`` objects."""

    task: str
    seed: int
    fps: int
    poses: np.ndarray
    """World poses ``(T, n, 7)``, xyzw."""
    tool: np.ndarray
    """o+ per frame ``(T,)`` int."""
    target: np.ndarray
    """o* per frame ``(T,)`` int."""
    waypoint: np.ndarray
    """w per frame ``(T, 7)``: the tool's goal pose in the target's frame."""
    waypoint_index: np.ndarray
    """Counter of way-points ``(T,)``; changes exactly where w changes."""
    grasped: np.ndarray
    """Whether the end-effector holds an object ``(T,)`` bool."""
    success: bool

    @property
    def frames(self) -> int:
        return int(self.poses.shape[0])


@dataclass
class PlanContext:
    """What a demonstrator plan may look at: the task, the poses, its own rng and, for a
    robot, how close its arm can bring the end-effector to a world pose."""

    task: Task
    rng: np.random.Generator
    poses: Callable[[], np.ndarray]
    reach_error: Callable[[list[np.ndarray]], float] | None = None
    """How far (m) the arm, from its present posture, falls short of a chain of world poses
    of object 0; ``None`` for the floating hand, which reaches every pose."""


class _Recorder:
    def __init__(self, scene: Scene, fps: int, tremor: Tremor | None) -> None:
        if SIM_HZ % fps:
            raise HspError(f"record.fps = {fps}: must divide the simulation rate {SIM_HZ} Hz")
        self.scene, self.fps, self.substeps, self.tremor = scene, fps, SIM_HZ // fps, tremor
        self.t = 0.0
        self.rows: list[tuple[np.ndarray, int, int, np.ndarray, int, bool]] = []
        self.label: tuple[int, int, np.ndarray, int] | None = None

    def frame(self) -> None:
        tool, target, w, k = self.label  # type: ignore[misc]
        self.rows.append((self.scene.object_poses(), tool, target, w, k, self.scene.ee.gripper.closed))

    def run(self, tcp_path: np.ndarray) -> None:
        """Follow TCP poses ``(K·substeps, 7)``, recording one frame per ``substeps``."""
        for i, T in enumerate(tcp_path):
            if self.tremor is not None:
                T = T.copy()
                T[:3] += self.tremor(np.array([self.t]))[0]
            self.scene.substep(T)
            self.t += 1.0 / SIM_HZ
            if (i + 1) % self.substeps == 0:
                self.frame()


def segment_duration(start: np.ndarray, goal: np.ndarray, move: Move, task: Task, rng: np.random.Generator) -> float:
    d = task.spec.demonstrator
    dist = np.linalg.norm(goal[:3] - start[:3]) + 0.1 * np.radians(rotation_angle_deg(start[3:], goal[3:]))
    return max(d.min_duration, dist / d.speed) * rng.uniform(*d.duration_jitter) * move.slow


def _bulge(start: np.ndarray, goal: np.ndarray, move: Move, task: Task, rng: np.random.Generator) -> np.ndarray:
    if move.straight:
        return np.zeros(3)
    delta = goal[:3] - start[:3]
    dist = np.linalg.norm(delta)
    scale = min(task.spec.demonstrator.curve, 0.3 * dist)
    side = np.cross(delta, [0, 0, 1.0])
    side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else np.zeros(3)
    return scale * (rng.uniform(0.3, 1.0) * np.array([0, 0, 1.0]) + rng.normal(0, 0.5) * side)


def execute(scene: Scene, steps: Iterator[Step], fps: int, rng: np.random.Generator) -> _Recorder:
    """Run a plan; returns the recorder holding one row per frame."""
    task, d = scene.task, scene.task.spec.demonstrator
    tremor = Tremor(d.tremor, rng) if d.tremor > 0 else None
    rec = _Recorder(scene, fps, tremor)
    waypoint_count = 0
    tcp = scene.ee.tcp_pose()
    for step in steps:
        if isinstance(step, Grasp):
            scene.grasp(step.obj)
            continue
        if isinstance(step, Release):
            scene.release()
            continue
        poses = scene.object_poses()
        goal_tool = compose(poses[step.target], step.pose)
        T_tcp_tool = relative(poses[step.tool], poses[0])
        goal = compose(goal_tool, inverse(T_tcp_tool)) if step.tool != 0 else goal_tool
        if rec.label is None:
            rec.label = (step.tool, step.target, step.pose, 0)
            rec.frame()
        rec.label = (step.tool, step.target, step.pose, waypoint_count)
        waypoint_count += 1
        n_frames = max(1, round(segment_duration(tcp, goal, step, task, rng) * fps))
        n_sub = n_frames * rec.substeps
        path = segment_poses(tcp, goal, np.arange(1, n_sub + 1) / n_sub, _bulge(tcp, goal, step, task, rng))
        pause = round(rng.uniform(*d.pause) * fps) * rec.substeps
        rec.run(np.concatenate([path, np.repeat(goal[None], pause, axis=0)]))
        tcp = goal
    if rec.label is None:
        raise HspError(f"{task.path}: the demonstrator made no move")
    return rec


def demonstrate(task: Task, seed: int, fps: int) -> Demonstration:
    """Draw a layout from ``seed``, run the task's demonstrator, check success."""
    rng = np.random.default_rng(seed)
    layout = sample_layout(task, rng)
    with Scene(task, layout, task.spec.demonstrator.embodiment) as scene:
        for _ in range(SIM_HZ // 4):
            scene.substep(layout[0] if task.spec.demonstrator.embodiment == "hand" else scene.ee.tcp_pose())
        ctx = PlanContext(task, rng, scene.object_poses, getattr(scene.ee, "reach_error", None))
        rec = execute(scene, PLANS[task.spec.kind](ctx), fps, rng)
    poses = np.stack([r[0] for r in rec.rows])
    return Demonstration(
        task=task.name,
        seed=seed,
        fps=fps,
        poses=poses,
        tool=np.array([r[1] for r in rec.rows], dtype=np.int16),
        target=np.array([r[2] for r in rec.rows], dtype=np.int16),
        waypoint=np.stack([r[3] for r in rec.rows]),
        waypoint_index=np.array([r[4] for r in rec.rows], dtype=np.int32),
        grasped=np.array([r[5] for r in rec.rows], dtype=bool),
        success=is_success(task, poses),
    )
