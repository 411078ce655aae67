"""``act`` and ``diffusion``: LeRobot's ACT and Diffusion Policy, state only, as LeRobot has them.

The policy classes, their configurations, their pre- and post-processors (normalisation)
and their optimiser presets are LeRobot's (``lerobot.policies``); hsp feeds them batches
laid out as a ``LeRobotDataset`` with ``delta_timestamps`` would (indices beyond an
episode clamped to its edge and flagged in ``action_is_pad``), from the same
demonstrations as bc (:mod:`~hsp.baselines.observations`):

* ``observation.state``: e_t's 9 numbers of o_t; ``observation.environment_state``: the
  other objects' ``9(n−1)`` (either policy needs both);
* ``action``: a_t ``(6,)`` and the gripper g_t as 0/1, so ``(7,)``; steps whose a_t was not
  observed are padding.

Statistics come from the training episodes with bc's floors on the spreads (a constant
feature would otherwise divide by 10⁻⁸ at test time). The LeRobot configuration's own
fields (chunk size, horizon, model sizes, learning rate) are ``params.yaml:
baselines.METHOD.policy``: LeRobot's defaults are GPU-sized. Closed loop, the agent feeds
o_t one step at a time to ``select_action`` (ACT's action queue, Diffusion's observation
history and queue run inside the policy) and moves e_t by the un-normalised a_t, the
gripper closed above ½.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from rich.progress import track

from hsp.baselines.common import ACT_MIN_STD, OBS_MIN_STD, BestCheckpoint, PoseAgent
from hsp.baselines.observations import POSE_FEATURES, Demonstrations
from hsp.errors import HspError
from hsp.fileio import atomic_path
from hsp.policy.train import split
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)

STATE, ENV, ACTION = "observation.state", "observation.environment_state", "action"
HSP_FILE = "hsp.json"


@dataclass(frozen=True)
class LeRobotPolicyConfig:
    """``params.yaml: baselines.act`` and ``baselines.diffusion``."""

    iterations: int = 3000
    """Gradient steps."""
    batch_size: int = 32
    """Frames per batch, drawn at random (each with its action chunk)."""
    policy: dict = field(default_factory=dict)
    """Fields of LeRobot's ``ACTConfig`` / ``DiffusionConfig`` (sizes, chunk, horizon, learning rate)."""
    moving_m: float = 0.002
    """The demonstrations' gripper labels g_t, as for bc (:func:`~hsp.baselines.observations.gripper_closed`)."""
    grasp_m: float = 0.01
    validation_every: int = 5
    """Every this-many-th episode validates; 0: none (the last iterate is kept)."""
    checkpoint_every: int = 100
    """Iterations between validations; the checkpoint with the lowest held-out loss is kept."""

    def __post_init__(self) -> None:
        if min(self.iterations, self.batch_size, self.checkpoint_every) < 1:
            raise HspError(f"baselines: iterations, batch_size and checkpoint_every must be ≥ 1, got {self}")


def _classes(method: str):
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy

    return {"act": (ACTConfig, ACTPolicy), "diffusion": (DiffusionConfig, DiffusionPolicy)}[method]


def policy_config(method: str, d_obs: int, overrides: dict):
    """LeRobot's configuration of ``method`` for o_t of ``d_obs`` numbers, CPU, every input
    normalised (LeRobot's default mapping leaves ``observation.environment_state`` raw)."""
    from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature

    config_class, _ = _classes(method)
    mode = NormalizationMode.MEAN_STD if method == "act" else NormalizationMode.MIN_MAX  # diffusion clips to [-1, 1]
    try:
        return config_class(
            device="cpu", push_to_hub=False,
            input_features={STATE: PolicyFeature(FeatureType.STATE, (POSE_FEATURES,)),
                            ENV: PolicyFeature(FeatureType.ENV, (d_obs - POSE_FEATURES,))},
            output_features={ACTION: PolicyFeature(FeatureType.ACTION, (7,))},
            normalization_mapping={"STATE": mode, "ENV": mode, "ACTION": mode}, **overrides)
    except (TypeError, ValueError, NotImplementedError) as e:
        raise HspError(f"baselines.{method}.policy: {str(e).strip().splitlines()[0]}") from None


def dataset_stats(demos: Demonstrations) -> dict[str, dict[str, np.ndarray]]:
    """LeRobot's statistics (mean, std, min, max per feature) of the demonstrations, spreads
    and ranges floored as bc's."""
    obs = np.concatenate(demos.obs)
    act = np.concatenate([np.c_[a, g][m] for a, g, m in zip(demos.action, demos.grip, demos.observed)])
    out = {}
    for key, x, floor in ((STATE, obs[:, :POSE_FEATURES], OBS_MIN_STD), (ENV, obs[:, POSE_FEATURES:], OBS_MIN_STD),
                          (ACTION, act, ACT_MIN_STD)):
        lo, hi = x.min(0), x.max(0)
        if key == ACTION:  # no step (a_t = 0) mid-range, not at an edge Diffusion's clipped sampling avoids
            hi = np.maximum(np.abs(lo), np.abs(hi))
            lo = -hi
        widen = np.maximum(2 * floor - (hi - lo), 0) / 2
        out[key] = {"mean": x.mean(0), "std": np.maximum(x.std(0), floor), "min": lo - widen, "max": hi + widen}
    return {k: {s: v.astype(np.float32) for s, v in d.items()} for k, d in out.items()}


def _deltas(indices) -> np.ndarray:
    return np.zeros(1, int) if indices is None else np.asarray(list(indices))


def batch(demos: Demonstrations, frames: np.ndarray, cfg) -> dict[str, torch.Tensor]:
    """The LeRobot batch of ``frames`` ``(B, 2)`` (episode, t): observations at t plus the
    policy's ``observation_delta_indices``, actions at t plus its ``action_delta_indices``,
    clamped to the episode and flagged in ``action_is_pad`` (also where a_t was not observed)."""
    lengths = np.array([len(o) for o in demos.obs])
    starts = np.r_[0, np.cumsum(lengths)[:-1]]
    obs = np.concatenate(demos.obs).astype(np.float32)
    act = np.concatenate([np.c_[a, g] for a, g in zip(demos.action, demos.grip)]).astype(np.float32)
    observed = np.concatenate(demos.observed)
    ep, t = frames[:, 0], frames[:, 1]

    def gather(deltas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = t[:, None] + deltas[None]
        outside = (i < 0) | (i >= lengths[ep][:, None])
        return starts[ep][:, None] + np.clip(i, 0, lengths[ep][:, None] - 1), outside

    oi, _ = gather(_deltas(cfg.observation_delta_indices))
    ai, outside = gather(_deltas(cfg.action_delta_indices))
    out = {STATE: obs[oi][..., :POSE_FEATURES], ENV: obs[oi][..., POSE_FEATURES:], ACTION: act[ai],
           "action_is_pad": outside | ~observed[ai]}
    if cfg.observation_delta_indices is None:  # ACT: one observation, no time axis
        out[STATE], out[ENV] = out[STATE][:, 0], out[ENV][:, 0]
    return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in out.items()}


def _all_frames(demos: Demonstrations) -> np.ndarray:
    return np.concatenate([np.c_[np.full(len(o), e), np.arange(len(o))] for e, o in enumerate(demos.obs)])


@dataclass
class LeRobotModel:
    policy: object
    """LeRobot's ACTPolicy or DiffusionPolicy."""
    pre: object
    post: object
    method: str
    objects: list[str]
    fps: int


@torch.no_grad()
def held_out_loss(model: LeRobotModel, demos: Demonstrations, seed: int, batch_size: int = 256) -> float:
    """The policy's own training loss over every held-out frame (in training mode: ACT's
    VAE term needs it; its dropout and Diffusion's noise drawn from ``seed``, apart from
    the training stream)."""
    frames, total = _all_frames(demos), 0.0
    model.policy.train()  # type: ignore[attr-defined]
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        for i in range(0, len(frames), batch_size):
            part = frames[i:i + batch_size]
            b = model.pre(batch(demos, part, model.policy.config))  # type: ignore[attr-defined]
            loss, _ = model.policy.forward(b)  # type: ignore[attr-defined]
            total += loss.item() * len(part)
    return total / len(frames)


def train(demos: Demonstrations, objects: list[str], method: str, cfg: LeRobotPolicyConfig, seed: int
          ) -> tuple[LeRobotModel, dict]:
    """LeRobot's ``method`` fitted to ``demos`` with its own loss, optimiser preset and
    scheduler; the checkpoint with the lowest held-out loss is kept."""
    from lerobot.policies.factory import make_pre_post_processors

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    fit_on, held = split(len(demos), cfg.validation_every)
    train_set, held_out = demos.subset(fit_on), demos.subset(held)
    pcfg = policy_config(method, demos.obs[0].shape[1], cfg.policy)
    policy = _classes(method)[1](pcfg)
    pre, post = make_pre_post_processors(pcfg, dataset_stats=dataset_stats(train_set))
    model = LeRobotModel(policy, pre, post, method, objects, demos.fps)
    opt_cfg = pcfg.get_optimizer_preset()
    optimizer = opt_cfg.build(policy.get_optim_params())
    sched_cfg = pcfg.get_scheduler_preset()
    scheduler = sched_cfg.build(optimizer, cfg.iterations) if sched_cfg is not None else None
    frames, best, report = _all_frames(train_set), BestCheckpoint(), {}
    log.info("train %s: %d episodes (%d frames), %d held out to validate; %.1f M parameters", method,
             len(train_set), len(frames), len(held_out), sum(p.numel() for p in policy.parameters()) / 1e6)
    for it in track(range(1, cfg.iterations + 1), description=f"train {method}"):
        policy.train()
        loss, _ = policy.forward(pre(batch(train_set, frames[rng.integers(len(frames), size=cfg.batch_size)], pcfg)))
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), opt_cfg.grad_clip_norm)
        optimizer.step()
        optimizer.zero_grad()
        if scheduler is not None:
            scheduler.step()
        report = {"loss": loss.item()}
        if len(held_out) and (it % cfg.checkpoint_every == 0 or it == cfg.iterations):
            score = held_out_loss(model, held_out, seed)
            best.offer(score, it, policy)
            log.info("iteration %d: training loss %.4f, held out %.4f", it, loss.item(), score)
    if best.restore(policy):
        report |= {"checkpoint_iteration": best.iteration, "validation_loss": best.score}
    report |= {"episodes": len(train_set), "frames": len(frames), "validation_episodes": len(held_out),
               "parameters": sum(p.numel() for p in policy.parameters())}
    policy.eval()
    return model, report


def save(model: LeRobotModel, cfg: LeRobotPolicyConfig, out_dir: Path) -> None:
    """LeRobot's ``save_pretrained`` of the policy and both processors, and ``hsp.json``;
    swapped in whole."""
    with atomic_path(Path(out_dir)) as tmp:
        tmp.mkdir()
        for part in (model.policy, model.pre, model.post):
            part.save_pretrained(tmp)  # type: ignore[attr-defined]
        (tmp / HSP_FILE).write_text(json.dumps({"method": model.method, "objects": model.objects, "fps": model.fps,
                                                "train": asdict(cfg)}, indent=2) + "\n")


def load(model_dir: Path, method: str) -> LeRobotModel:
    """A model written by :func:`save`; a one-line error naming the directory otherwise."""
    from lerobot.policies.factory import make_pre_post_processors

    model_dir = Path(model_dir)
    if not (model_dir / HSP_FILE).is_file() or not (model_dir / "model.safetensors").is_file():
        raise HspError(f"{model_dir}: not a trained {method} model (needs {HSP_FILE} and LeRobot's "
                       f"model.safetensors; run `hsp train --method {method}`)")
    try:
        meta = json.loads((model_dir / HSP_FILE).read_text())
        if meta.get("method") != method:
            raise HspError(f"{model_dir}: a {meta.get('method') or 'non-baseline'} model, not {method}")
        with contextlib.redirect_stdout(io.StringIO()):  # LeRobot prints "Loading weights" per load
            policy = _classes(method)[1].from_pretrained(model_dir)
        pre, post = make_pre_post_processors(policy.config, pretrained_path=str(model_dir))
    except (ValueError, KeyError, TypeError, RuntimeError, OSError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise HspError(f"{model_dir}: not a trained {method} model of this hsp version (retrain with `hsp train`): "
                       f"{first}") from None
    return LeRobotModel(policy.eval(), pre, post, method, meta["objects"], int(meta["fps"]))


class LeRobotAgent(PoseAgent):
    """Closed loop through ``select_action``: o_t in, one action out per step."""

    def __init__(self, model: LeRobotModel, task: Task, source: str = "model") -> None:
        d_obs = POSE_FEATURES + int(model.policy.config.input_features[ENV].shape[0])  # type: ignore[attr-defined]
        super().__init__(model.objects, d_obs, task, source)
        self.model = model

    def reset(self, poses: np.ndarray, seed: int) -> None:
        super().reset(poses, seed)
        self.model.policy.reset()  # type: ignore[attr-defined]
        self.generator_seed = seed

    @torch.no_grad()
    def act(self, poses: np.ndarray) -> np.ndarray:
        o = torch.from_numpy(self.observation(poses)).float()
        with torch.random.fork_rng():  # Diffusion's sampling noise: the episode's own stream
            torch.manual_seed(self.generator_seed)
            chosen = self.model.policy.select_action(  # type: ignore[attr-defined]
                self.model.pre({STATE: o[:POSE_FEATURES], ENV: o[POSE_FEATURES:]}))  # type: ignore[operator]
            a = self.model.post(chosen)[0].double().numpy()  # type: ignore[operator]
            self.generator_seed = int(torch.randint(2**31, ()).item())
        return self.move(poses[0], a[:6], bool(a[6] > 0.5))
