"""``gail``: Generative Adversarial Imitation Learning (Ho & Ermon, 2016) on PPO.

A discriminator D(o_t, u_t) learns to tell the demonstrations' (observation, action) pairs
from the policy's; its logit, log D − log(1 − D), is the reward that PPO
(stable-baselines3's, unchanged) maximises in the task's own environment. The logit rather
than −log(1 − D): that reward is always positive, so it pays to prolong an episode, and an
episode here ends at success. The task's success is never a reward.

The policy sees and does what BC does (:mod:`~hsp.baselines.bc`): o_t standardised by the
demonstrations' spread, u_t = (a_t standardised ``(6,)``, gripper ``(1,)``: closed when
positive), turned into the environment's command by
:meth:`~hsp.baselines.common.PoseAgent.move`. After each PPO rollout D takes
``disc_updates`` Adam steps on batches of demonstration and rollout pairs; the rollout's
rewards then become D's logits (SB3's bootstrap of episodes cut by the step limit kept),
and PPO updates. Training layouts come from their own seed stream, not evaluation's.

``imitation`` (the reference GAIL on SB3) pins gymnasium 0.29, which LeRobot's gymnasium
≥ 1.1 excludes; the discriminator and the reward relabelling are the small part written here.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from safetensors.torch import load_file, save_file
from torch import nn

from hsp.baselines.common import FORMAT, PoseAgent, scales
from hsp.baselines.observations import Demonstrations
from hsp.errors import HspError
from hsp.evaluation.env import world_poses
from hsp.fileio import atomic_path
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)

U_LIMIT = 5.0
"""Bound of each standardised action number (the demonstrations' lie within about ±3)."""
TRAIN_STREAM = 0x6A11
"""Seed stream of training layouts (evaluation draws its layouts from another)."""


@dataclass(frozen=True)
class GailConfig:
    """``params.yaml: baselines.gail``."""

    timesteps: int = 200_000
    """Environment steps of PPO (the budget)."""
    envs: int = 2
    """Environments stepped together, each rollout holding ``n_steps`` of each."""
    processes: bool = True
    """Each environment in its own process (PyBullet's clients; ``make_env`` must pickle)."""
    n_steps: int = 1024
    """Steps per environment in each rollout."""
    batch_size: int = 256
    epochs: int = 5
    """PPO's passes over each rollout."""
    learning_rate: float = 3e-4
    gamma: float = 0.99
    hidden: int = 256
    """Units of each hidden layer, policy, value and discriminator alike."""
    log_std_init: float = -1.0
    """PPO's initial log-spread of u_t (0: the demonstrations' own spread of a_t)."""
    layers: int = 2
    disc_updates: int = 50
    """Discriminator steps after each rollout."""
    disc_batch: int = 512
    """Pairs of each kind per discriminator step."""
    disc_learning_rate: float = 1e-3
    moving_m: float = 0.002
    """The demonstrations' gripper labels g_t, as for bc (:func:`~hsp.baselines.observations.gripper_closed`)."""
    grasp_m: float = 0.01

    def __post_init__(self) -> None:
        if min(self.timesteps, self.envs, self.n_steps, self.batch_size, self.epochs, self.hidden, self.layers,
               self.disc_updates, self.disc_batch) < 1:
            raise HspError(f"baselines.gail: every count must be ≥ 1, got {self}")


def mlp(d_in: int, hidden: int, layers: int, d_out: int) -> nn.Sequential:
    out: list[nn.Module] = []
    for _ in range(layers):
        out += [nn.Linear(d_in, hidden), nn.Tanh()]
        d_in = hidden
    return nn.Sequential(*out, nn.Linear(d_in, d_out))


def pairs(obs: np.ndarray, u: np.ndarray) -> torch.Tensor:
    """D's input ``(N, d + 7)`` from standardised o_t ``(N, d)`` and u_t ``(N, 7)`` as the
    environment executes them: clipped, the gripper as ±1."""
    u = np.clip(u, -U_LIMIT, U_LIMIT)
    return torch.from_numpy(np.concatenate([obs, u[:, :6], np.where(u[:, 6:] > 0, 1.0, -1.0)], axis=1)).float()


class ImitationEnv(gym.Wrapper):
    """A task environment as the policy sees it: o_t standardised ``(9n,)``, u_t ``(7,)``
    (:func:`pairs`); reward 0 (the trainer writes D's into each rollout)."""

    def __init__(self, env: gym.Env, task: Task, scale: dict[str, np.ndarray]) -> None:
        super().__init__(env)
        self.scale = scale
        self.agent = PoseAgent(task.names, len(scale["obs_mean"]), task, "gail")
        d = len(scale["obs_mean"])
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (d,), np.float32)
        self.action_space = gym.spaces.Box(-U_LIMIT, U_LIMIT, (7,), np.float32)

    def _observe(self, obs: dict) -> np.ndarray:
        self.poses = world_poses(obs)
        o = (self.agent.observation(self.poses) - self.scale["obs_mean"]) / self.scale["obs_std"]
        return o.astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.agent.reset(world_poses(obs), 0)
        return self._observe(obs), info

    def step(self, u: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        u = np.clip(np.asarray(u, np.float64), -U_LIMIT, U_LIMIT)
        step = self.scale["act_mean"] + self.scale["act_std"] * u[:6]
        obs, _, terminated, truncated, info = self.env.step(self.agent.move(self.poses[0], step, bool(u[6] > 0)))
        return self._observe(obs), 0.0, terminated, truncated, info


def _imitation_env(make_env: Callable[[], gym.Env], task: Task, scale: dict[str, np.ndarray]) -> gym.Env:
    from stable_baselines3.common.monitor import Monitor

    return Monitor(ImitationEnv(make_env(), task, scale))


@dataclass
class GailModel:
    ppo: object
    """stable_baselines3.PPO"""
    disc: nn.Sequential
    scale: dict[str, np.ndarray]
    objects: list[str]
    fps: int


def _adversary(disc: nn.Sequential, expert: torch.Tensor, cfg: GailConfig, rng: np.random.Generator,
               history: list[dict]):
    """The SB3 callback that trains D on each rollout and relabels its rewards with D's logits."""
    from stable_baselines3.common.callbacks import BaseCallback

    opt = torch.optim.Adam(disc.parameters(), lr=cfg.disc_learning_rate)
    bce = nn.functional.binary_cross_entropy_with_logits

    class Adversary(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            buf = self.model.rollout_buffer
            policy = pairs(buf.observations.reshape(-1, buf.observations.shape[-1]),
                           buf.actions.reshape(-1, buf.actions.shape[-1]))
            for _ in range(cfg.disc_updates):
                e = expert[rng.integers(len(expert), size=cfg.disc_batch)]
                p = policy[rng.integers(len(policy), size=cfg.disc_batch)]
                loss = bce(disc(e)[:, 0], torch.ones(len(e))) + bce(disc(p)[:, 0], torch.zeros(len(p)))
                opt.zero_grad()
                loss.backward()
                opt.step()
            with torch.no_grad():
                logit = disc(policy)[:, 0].numpy()
                expert_right = (disc(expert[rng.integers(len(expert), size=cfg.disc_batch)])[:, 0] > 0).float().mean()
            buf.rewards += logit.reshape(buf.rewards.shape)  # the environment's are 0; SB3's bootstrap stays
            buf.compute_returns_and_advantage(last_values=self.locals["values"], dones=self.locals["dones"])
            successes = list(self.model.ep_success_buffer)
            history.append({"timesteps": self.num_timesteps, "disc_loss": loss.item(),
                            "disc_policy_right": float((logit < 0).mean()), "disc_expert_right": expert_right.item(),
                            "reward": float(logit.mean()),
                            "success_recent": float(np.mean(successes)) if successes else 0.0})
            log.info("gail %d of %d steps: D tells %.2f of the policy's pairs and %.2f of the demonstrations', "
                     "reward %.2f, success of recent episodes %.2f", self.num_timesteps, cfg.timesteps,
                     history[-1]["disc_policy_right"], history[-1]["disc_expert_right"], history[-1]["reward"],
                     history[-1]["success_recent"])

    return Adversary()


def train(demos: Demonstrations, task: Task, make_env: Callable[[], gym.Env], cfg: GailConfig, seed: int
          ) -> tuple[GailModel, dict]:
    """PPO on D's reward in the environments of ``make_env``, D against ``demos``; the model
    and a report."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    torch.manual_seed(seed)
    rng = np.random.default_rng([seed, TRAIN_STREAM])
    scale = scales(demos)
    obs = np.concatenate([o[m] for o, m in zip(demos.obs, demos.observed)])
    act = np.concatenate([a[m] for a, m in zip(demos.action, demos.observed)])
    grip = np.concatenate([g[m] for g, m in zip(demos.grip, demos.observed)])
    u = np.c_[(act - scale["act_mean"]) / scale["act_std"], np.where(grip, 1.0, -1.0)]
    expert = pairs((obs - scale["obs_mean"]) / scale["obs_std"], u)
    disc = mlp(expert.shape[1], cfg.hidden, cfg.layers, 1)
    factories = [partial(_imitation_env, make_env, task, scale)] * cfg.envs
    venv = SubprocVecEnv(factories) if cfg.processes and cfg.envs > 1 else DummyVecEnv(factories)
    ppo = PPO("MlpPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.epochs,
              learning_rate=cfg.learning_rate, gamma=cfg.gamma, seed=seed, device="cpu", verbose=0,
              policy_kwargs={"net_arch": [cfg.hidden] * cfg.layers, "log_std_init": cfg.log_std_init})
    ppo.set_logger(Logger(None, []))  # SB3's default logger makes an empty /tmp/SB3-DATE directory per learn()
    venv.seed(int(np.random.SeedSequence([seed, TRAIN_STREAM]).generate_state(1)[0]))  # after PPO's own seeding
    history: list[dict] = []
    start = time.perf_counter()
    log.info("train gail: %d demonstration pairs, PPO for %d environment steps in %d environments",
             len(expert), cfg.timesteps, cfg.envs)
    try:
        ppo.learn(cfg.timesteps, callback=_adversary(disc, expert, cfg, rng, history))
    finally:
        venv.close()
    seconds = time.perf_counter() - start
    last = history[-1] if history else {}
    report = {"timesteps": int(ppo.num_timesteps), "steps_per_second": ppo.num_timesteps / seconds,
              "episodes": len(demos), "frames": int(sum(len(o) for o in demos.obs)), "rollouts": len(history),
              **{f"last_{k}": v for k, v in last.items() if k != "timesteps"}}
    return GailModel(ppo, disc.eval(), scale, task.names, demos.fps), report


def save(model: GailModel, cfg: GailConfig, out_dir: Path) -> None:
    """``ppo.zip`` (SB3's format), ``discriminator.safetensors`` and ``config.json``; swapped in whole."""
    with atomic_path(Path(out_dir)) as tmp:
        tmp.mkdir()
        model.ppo.save(tmp / "ppo.zip")  # type: ignore[attr-defined]
        save_file({k: v.contiguous() for k, v in model.disc.state_dict().items()}, tmp / "discriminator.safetensors")
        config = {"format": FORMAT, "method": "gail", "objects": model.objects, "fps": model.fps,
                  "scale": {k: v.tolist() for k, v in model.scale.items()}, "train": asdict(cfg)}
        (tmp / "config.json").write_text(json.dumps(config, indent=2) + "\n")


def load(model_dir: Path, method: str = "gail") -> GailModel:
    """A model written by :func:`save`; a one-line error naming the directory otherwise."""
    from stable_baselines3 import PPO

    model_dir = Path(model_dir)
    if not all((model_dir / f).is_file() for f in ("config.json", "ppo.zip", "discriminator.safetensors")):
        raise HspError(f"{model_dir}: not a trained gail model (needs config.json, ppo.zip and "
                       f"discriminator.safetensors; run `hsp train --method gail`)")
    try:
        config = json.loads((model_dir / "config.json").read_text())
        if config.get("method") != "gail":
            raise HspError(f"{model_dir}: a {config.get('method') or 'non-baseline'} model, not gail")
        if config.get("format") != FORMAT:
            raise ValueError(f"model format {config.get('format')}, this hsp reads {FORMAT}")
        cfg = GailConfig(**config["train"])
        scale = {k: np.asarray(v) for k, v in config["scale"].items()}
        disc = mlp(len(scale["obs_mean"]) + 7, cfg.hidden, cfg.layers, 1)
        disc.load_state_dict(load_file(model_dir / "discriminator.safetensors"))
        ppo = PPO.load(model_dir / "ppo.zip", device="cpu")
    except (ValueError, KeyError, TypeError, RuntimeError, OSError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise HspError(f"{model_dir}: not a trained gail model of this hsp version (retrain with `hsp train`): "
                       f"{first}") from None
    return GailModel(ppo, disc.eval(), scale, config["objects"], int(config["fps"]))


class GailAgent(PoseAgent):
    """Closed loop: PPO's mean action."""

    def __init__(self, model: GailModel, task: Task, source: str = "model") -> None:
        super().__init__(model.objects, len(model.scale["obs_mean"]), task, source)
        self.model = model

    def act(self, poses: np.ndarray) -> np.ndarray:
        s = self.model.scale
        obs = ((self.observation(poses) - s["obs_mean"]) / s["obs_std"]).astype(np.float32)
        u, _ = self.model.ppo.predict(obs, deterministic=True)  # type: ignore[attr-defined]
        u = np.clip(np.asarray(u, np.float64), -U_LIMIT, U_LIMIT)
        return self.move(poses[0], s["act_mean"] + s["act_std"] * u[:6], bool(u[6] > 0))
