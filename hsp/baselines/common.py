"""What the low-level baselines share: their configuration, the Gaussian policy network,
batches of demonstrations, the per-frame likelihood, saving and loading, and the
closed-loop agent's reading of the scene and its command."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from torch import nn

from hsp.baselines.observations import POSE_FEATURES, Demonstrations, flat_observation
from hsp.errors import HspError
from hsp.evaluation.env import GRIP_CLOSED
from hsp.evaluation.proposed import SHORTFALL_M, with_shortfall
from hsp.fileio import atomic_path
from hsp.geometry import apply_rotvec_delta
from hsp.labeling.label import canonical_poses
from hsp.tasks.registry import Task

FORMAT = 1
"""Layout of saved baseline models; others are refused with a clear message."""
LOG_STD_RANGE = (-5.0, 2.0)
OBS_MIN_STD = 0.01
"""Floor of an observation feature's spread when standardising: a resting block's height
varies by 0.35 mm over the demonstrations, so a 1 mm settling difference in closed loop
would otherwise read as three standard deviations."""
ACT_MIN_STD = 1e-4


@dataclass(frozen=True)
class BaselineConfig:
    """``params.yaml: baselines.METHOD``."""

    iterations: int = 2000
    """Gradient steps."""
    batch_steps: int = 1024
    """Frames per batch (drawn at random for bc; whole episodes until they hold this many
    for bc-rnn and taco)."""
    hidden: int = 256
    """Units of each hidden layer (and of the LSTM)."""
    layers: int = 2
    """Hidden layers of each MLP."""
    learning_rate: float = 1e-3
    """Adam's step size."""
    moving_m: float = 0.002
    """m per frame above which an object counts as moving, for the gripper labels g_t."""
    grasp_m: float = 0.01
    """m within which the hand's offset from an object counts as the grasp it carries it by (g_t)."""
    validation_every: int = 5
    """Every this-many-th episode validates; 0: none (the last iterate is kept)."""
    checkpoint_every: int = 50
    """Iterations between validations; the checkpoint best on the held-out episodes is kept."""

    def __post_init__(self) -> None:
        if min(self.iterations, self.batch_steps, self.hidden, self.layers, self.checkpoint_every) < 1:
            raise HspError(f"baselines: iterations, batch_steps, hidden, layers and checkpoint_every must be ≥ 1, "
                           f"got {self}")


class GaussianPolicy(nn.Module):
    """o_≤t → mean of a_t (standardised), its log-spread (learnt, the same in every state:
    a spread read from the state shrinks on the training frames and blows the held-out
    likelihood up) and logits: the gripper's, then any a method adds (TACO's stop)."""

    def __init__(self, d_obs: int, hidden: int, layers: int, recurrent: bool = False, logits: int = 1) -> None:
        super().__init__()
        self.lstm = nn.LSTM(d_obs, hidden, batch_first=True) if recurrent else None
        d, body = (hidden if recurrent else d_obs), []
        for _ in range(layers):
            body += [nn.Linear(d, hidden), nn.ReLU()]
            d = hidden
        self.body = nn.Sequential(*body)
        self.head = nn.Linear(hidden, 6 + logits)
        self.log_std = nn.Parameter(torch.zeros(6))
        for name in ("obs_mean", "obs_std", "act_mean", "act_std"):
            self.register_buffer(name, torch.zeros(6 if name.startswith("act") else d_obs))

    def forward(self, obs: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, tuple[torch.Tensor, torch.Tensor] | None]:
        """``obs (B, T, d)`` raw → mean, log-std ``(B, T, 6)``, logits ``(B, T, logits)`` (the
        gripper's first), LSTM state."""
        x = (obs - self.obs_mean) / self.obs_std
        if self.lstm is not None:
            x, state = self.lstm(x, state)
        out = self.head(self.body(x))
        return out[..., :6], self.log_std.clamp(*LOG_STD_RANGE).expand_as(out[..., :6]), out[..., 6:], state

    def standardise(self, demos: Demonstrations) -> None:
        """Set the input and action scales from the training demonstrations."""
        for name, x in scales(demos).items():
            getattr(self, name).copy_(torch.from_numpy(x))


def scales(demos: Demonstrations) -> dict[str, np.ndarray]:
    """Mean and spread of o_t and of a_t over the demonstrations' (observed) steps:
    ``obs_mean``, ``obs_std``, ``act_mean``, ``act_std`` (spreads floored)."""
    obs = np.concatenate(demos.obs)
    act = np.concatenate([a[o] for a, o in zip(demos.action, demos.observed)])
    return {"obs_mean": obs.mean(0), "obs_std": np.maximum(obs.std(0), OBS_MIN_STD),
            "act_mean": act.mean(0), "act_std": np.maximum(act.std(0), ACT_MIN_STD)}


def frame_nll(net: GaussianPolicy, b: dict[str, torch.Tensor], mean: torch.Tensor, log_std: torch.Tensor,
              logits: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per frame ``(B, T)``: −log π(a_t) where the step was observed (0 elsewhere;
    standardised units, constant dropped) and −log π(g_t)."""
    a = (b["action"] - net.act_mean) / net.act_std
    nll = (0.5 * ((a - mean) / log_std.exp()) ** 2 + log_std).sum(-1) * b["observed"]
    bce = nn.functional.binary_cross_entropy_with_logits(logits[..., 0], b["grip"].float(), reduction="none")
    return nll, bce


def episode_batch(demos: Demonstrations, idx: list[int]) -> dict[str, torch.Tensor]:
    """Episodes ``idx`` padded to the longest: obs, action, grip, observed, present ``(B, T, ...)``."""
    T = max(len(demos.obs[i]) for i in idx)

    def pad(x: np.ndarray) -> np.ndarray:
        return np.concatenate([x, np.zeros((T - len(x),) + x.shape[1:], x.dtype)])

    out = {k: torch.from_numpy(np.stack([pad(getattr(demos, k)[i]) for i in idx]))
           for k in ("obs", "action", "grip", "observed")}
    out["present"] = torch.from_numpy(np.stack([pad(np.ones(len(demos.obs[i]), bool)) for i in idx]))
    return {k: v.float() if v.dtype == torch.float64 else v for k, v in out.items()}


def whole_episodes(rng: np.random.Generator, lengths: np.ndarray, batch_steps: int) -> list[int]:
    """Episodes in random order until they hold ``batch_steps`` frames."""
    order = rng.permutation(len(lengths))
    return list(order[:int(np.searchsorted(np.cumsum(lengths[order]), batch_steps)) + 1])


def save_model(net: nn.Module, config: dict, out_dir: Path) -> None:
    """Weights (safetensors) and ``config.json`` (with :data:`FORMAT`); the directory is
    swapped in whole."""
    with atomic_path(Path(out_dir)) as tmp:
        tmp.mkdir()
        save_file({k: v.contiguous() for k, v in net.state_dict().items()}, tmp / "model.safetensors")
        (tmp / "config.json").write_text(json.dumps({"format": FORMAT, **config}, indent=2) + "\n")


def load_model(model_dir: Path, method: str, build: Callable[[dict], nn.Module]) -> tuple[nn.Module, dict]:
    """The network and config of a model written by :func:`save_model` for ``method``
    (``build`` makes the network from the config); a one-line error naming the directory
    otherwise."""
    model_dir = Path(model_dir)
    if not (model_dir / "config.json").is_file() or not (model_dir / "model.safetensors").is_file():
        raise HspError(f"{model_dir}: not a trained {method} model (needs config.json and model.safetensors; "
                       f"run `hsp train --method {method}`)")
    try:
        config = json.loads((model_dir / "config.json").read_text())
        if config.get("method") != method:
            raise HspError(f"{model_dir}: a {config.get('method') or 'non-baseline'} model, not {method}")
        if config.get("format") != FORMAT:
            raise ValueError(f"model format {config.get('format')}, this hsp reads {FORMAT}")
        net = build(config)
        net.load_state_dict(load_file(model_dir / "model.safetensors"))
        return net.eval(), config
    except (SafetensorError, ValueError, KeyError, TypeError, RuntimeError, OSError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise HspError(f"{model_dir}: not a trained {method} model of this hsp version (retrain with `hsp train`): "
                       f"{first}") from None


class PoseAgent:
    """A closed-loop agent reading world poses ``(n, 7)``: ``reset(poses, seed)``, then
    ``act(poses) -> (8,)`` per control step (subclasses)."""

    def __init__(self, objects: list[str], d_obs: int, task: Task, source: str) -> None:
        if objects != task.names:
            raise HspError(f"{source}: a model for objects {objects}, not those of task {task.name!r} {task.names}")
        if d_obs != POSE_FEATURES * len(task.names):
            raise HspError(f"{source}: observations of {d_obs} numbers, task {task.name!r} has "
                           f"{POSE_FEATURES * len(task.names)}")
        self.symmetries = [o.symmetry for o in task.objects]

    def reset(self, poses: np.ndarray, seed: int) -> None:
        self.first = np.asarray(poses, np.float64).copy()
        self.last: np.ndarray | None = None

    def observation(self, poses: np.ndarray) -> np.ndarray:
        """o_t ``(9n,)``, symmetric objects made canonical by the episode's first frame."""
        return flat_observation(canonical_poses(np.stack([self.first, poses]), self.symmetries)[1])

    def observe(self, poses: np.ndarray) -> torch.Tensor:
        """o_t as a network's input ``(1, 1, 9n)``."""
        return torch.from_numpy(self.observation(poses)).float()[None, None]

    def command(self, net: GaussianPolicy, ee: np.ndarray, mean: torch.Tensor, grip_logit: torch.Tensor) -> np.ndarray:
        """:meth:`move` by the mean of a_t (standardised ``(6,)``), the gripper closed when its
        logit is positive."""
        return self.move(ee, (mean * net.act_std + net.act_mean).double().numpy(), grip_logit.item() > 0)

    def move(self, ee: np.ndarray, step: np.ndarray, closed: bool) -> np.ndarray:
        """The environment's action ``(8,)``: e_t ``(7,)`` moved by a_t ``(6,)`` plus the arm's
        shortfall on the last command (as the hierarchy's runner does,
        :func:`~hsp.evaluation.proposed.with_shortfall`: a hand's steps replayed from where a
        lagging arm is seen ended 4-6 cm from where the hand went, stacking-1), and the gripper."""
        target = apply_rotvec_delta(ee, step)
        if self.last is not None:
            target = with_shortfall(target, ee, self.last, SHORTFALL_M)
        self.last = target
        return np.concatenate([target, [GRIP_CLOSED if closed else 0]])


class BestCheckpoint:
    """The weights with the lowest held-out score seen so far."""

    def __init__(self) -> None:
        self.score, self.iteration, self.state = float("inf"), 0, None

    def offer(self, score: float, iteration: int, net: nn.Module) -> None:
        if score < self.score:
            self.score, self.iteration, self.state = score, iteration, copy.deepcopy(net.state_dict())

    def restore(self, net: nn.Module) -> bool:
        """Load the kept weights into ``net``; False when nothing was validated."""
        if self.state is not None:
            net.load_state_dict(self.state)
        return self.state is not None
