"""``bc`` and ``bc-rnn``: behavioural cloning of the end-effector's motion.

``bc`` is the paper's BC baseline: π(a_t, g_t | o_t), a Gaussian policy over the action
a_t (mean and diagonal spread from an MLP, in units of the data's spread) and a Bernoulli
over the gripper g_t, on the flat observation o_t (:mod:`~hsp.baselines.observations`),
trained by maximum likelihood on every frame whose step was observed. ``bc-rnn`` is the
same with an LSTM over the whole observation history o_≤t (robomimic's BC-RNN, which
resets its memory every ten steps; here it runs over the whole episode, as it is trained,
so that a comparison with the hierarchy does not hinge on memory alone).

Training draws frames at random (bc) or whole episodes from their start (bc-rnn) until a
batch holds ``batch_steps`` frames; every ``validation_every``-th episode is held out and
the checkpoint kept is the one with the lowest negative log-likelihood on it.

In closed loop the agent commands the end-effector moved by the mean of a_t from where it
is observed, and closes the gripper when p(g_t) > ½ (the environment then holds the
nearest object within reach, :data:`~hsp.evaluation.env.GRIP_CLOSED`).
"""

from __future__ import annotations

import copy
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from rich.progress import track
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from torch import nn

from hsp.baselines.observations import POSE_FEATURES, Demonstrations, flat_observation
from hsp.errors import HspError
from hsp.evaluation.env import GRIP_CLOSED
from hsp.fileio import atomic_path
from hsp.geometry import apply_rotvec_delta
from hsp.labeling.label import canonical_poses
from hsp.policy.train import split
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)

FORMAT = 1
LOG_STD_RANGE = (-5.0, 2.0)
MIN_STD = 1e-4
"""Floor of a feature's spread when standardising (a coordinate that never changes)."""


@dataclass(frozen=True)
class BCConfig:
    iterations: int = 5000
    """Gradient steps."""
    batch_steps: int = 1024
    """Frames per batch (bc-rnn: whole episodes until they hold this many)."""
    hidden: int = 256
    """Units of each hidden layer (and of the LSTM)."""
    layers: int = 2
    """Hidden layers of the MLP (after the LSTM for bc-rnn)."""
    learning_rate: float = 1e-3
    """Adam's step size."""
    moving_m: float = 0.002
    """m per frame above which an object counts as moving, for the gripper labels g_t."""
    validation_every: int = 5
    """Every this-many-th episode validates; 0: none (the last iterate is kept)."""
    checkpoint_every: int = 500
    """Iterations between validations."""

    def __post_init__(self) -> None:
        if min(self.iterations, self.batch_steps, self.hidden, self.layers, self.checkpoint_every) < 1:
            raise HspError(f"baselines: iterations, batch_steps, hidden, layers and checkpoint_every must be ≥ 1, "
                           f"got {self}")


class GaussianPolicy(nn.Module):
    """o_≤t → mean of a_t (standardised), its log-spread (learnt, the same in every state:
    a spread read from the state shrinks on the training frames and blows the held-out
    likelihood up) and logits: the gripper's, then any a method adds (TACO's stop)."""

    def __init__(self, d_obs: int, hidden: int, layers: int, recurrent: bool, logits: int = 1) -> None:
        super().__init__()
        self.recurrent = recurrent
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


@dataclass
class BCModel:
    net: GaussianPolicy
    method: str
    objects: list[str]
    fps: int


def episode_batch(demos: Demonstrations, idx: list[int]) -> dict[str, torch.Tensor]:
    """Episodes ``idx`` padded to the longest: obs, action, grip, observed, present ``(B, T, ...)``."""
    T = max(len(demos.obs[i]) for i in idx)

    def pad(x: np.ndarray) -> np.ndarray:
        return np.concatenate([x, np.zeros((T - len(x),) + x.shape[1:], x.dtype)])

    out = {k: torch.from_numpy(np.stack([pad(getattr(demos, k)[i]) for i in idx])) for k in ("obs", "action", "grip",
                                                                                            "observed")}
    out["present"] = torch.from_numpy(np.stack([pad(np.ones(len(demos.obs[i]), bool)) for i in idx]))
    return {k: v.float() if v.dtype == torch.float64 else v for k, v in out.items()}


def _frames(b: dict[str, torch.Tensor], rows: np.ndarray) -> dict[str, torch.Tensor]:
    """The frames ``rows`` of a batch flattened over episodes, as a batch of one-frame episodes."""
    return {k: v.reshape((-1,) + v.shape[2:])[torch.from_numpy(rows)][:, None] for k, v in b.items()}


def frame_nll(net: GaussianPolicy, b: dict[str, torch.Tensor], mean: torch.Tensor, log_std: torch.Tensor,
              logits: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per frame ``(B, T)``: −log π(a_t) where the step was observed (0 elsewhere;
    standardised units, constant dropped) and −log π(g_t)."""
    a = (b["action"] - net.act_mean) / net.act_std
    nll = (0.5 * ((a - mean) / log_std.exp()) ** 2 + log_std).sum(-1) * b["observed"]
    bce = nn.functional.binary_cross_entropy_with_logits(logits[..., 0], b["grip"].float(), reduction="none")
    return nll, bce


def losses(net: GaussianPolicy, b: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """−log π(a_t) over frames whose step was observed and −log π(g_t) over every frame."""
    mean, log_std, logits, _ = net(b["obs"])
    nll, bce = frame_nll(net, b, mean, log_std, logits)
    observed, present = b["observed"], b["present"]
    return {"action": nll.sum() / observed.sum().clamp(min=1), "grip": (bce * present).sum() / present.sum().clamp(min=1)}


def standardise(net: GaussianPolicy, demos: Demonstrations) -> None:
    obs = np.concatenate(demos.obs)
    act = np.concatenate([a[o] for a, o in zip(demos.action, demos.observed)])
    for name, x in (("obs", obs), ("act", act)):
        getattr(net, f"{name}_mean").copy_(torch.from_numpy(x.mean(0)))
        getattr(net, f"{name}_std").copy_(torch.from_numpy(np.maximum(x.std(0), MIN_STD)))


@torch.no_grad()
def validate(net: GaussianPolicy, demos: Demonstrations) -> dict[str, float]:
    """Held-out figures: the loss terms, the mean action's error (mm, and degrees of turn) on
    observed steps, and how often the gripper is right."""
    net.eval()
    b = episode_batch(demos, list(range(len(demos))))
    parts = losses(net, b)
    mean, _, logits, _ = net(b["obs"])
    pred = mean * net.act_std + net.act_mean
    observed, present = b["observed"], b["present"]
    err_mm = 1000 * (pred[..., :3] - b["action"][..., :3]).norm(dim=-1)
    err_deg = torch.rad2deg((pred[..., 3:] - b["action"][..., 3:]).norm(dim=-1))
    grip_right = ((logits[..., 0] > 0) == b["grip"]).float()
    net.train()
    return {"nll_action": parts["action"].item(), "nll_grip": parts["grip"].item(),
            "action_error_mm": (err_mm[observed].mean()).item(), "action_error_deg": (err_deg[observed].mean()).item(),
            "grip_accuracy": (grip_right[present].mean()).item()}


def train(demos: Demonstrations, objects: list[str], method: str, cfg: BCConfig, seed: int) -> tuple[BCModel, dict]:
    """π fitted to ``demos`` by maximum likelihood (``method``: ``bc`` or ``bc-rnn``); the
    model and a report (last losses, held-out figures of the checkpoint kept)."""
    recurrent = method == "bc-rnn"
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    fit_on, held = split(len(demos), cfg.validation_every)
    train_set, held_out = demos.subset(fit_on), demos.subset(held)
    net = GaussianPolicy(demos.obs[0].shape[1], cfg.hidden, cfg.layers, recurrent)
    standardise(net, train_set)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    lengths = np.array([len(o) for o in train_set.obs])
    whole = episode_batch(train_set, list(range(len(train_set))))
    frames = np.flatnonzero(whole["present"].reshape(-1).numpy())
    best: tuple[float, int, dict] | None = None
    report: dict[str, float | int] = {}
    log.info("train %s: %d episodes (%d frames), %d held out to validate", method, len(train_set), lengths.sum(),
             len(held_out))
    for it in track(range(1, cfg.iterations + 1), description=f"train {method}"):
        if recurrent:
            order = rng.permutation(len(train_set))
            take = int(np.searchsorted(np.cumsum(lengths[order]), cfg.batch_steps)) + 1
            b = episode_batch(train_set, list(order[:take]))
        else:
            b = _frames(whole, rng.choice(frames, min(cfg.batch_steps, len(frames)), replace=False))
        parts = losses(net, b)
        loss = sum(parts.values())
        opt.zero_grad()
        loss.backward()
        opt.step()
        report = {f"loss_{k}": v.item() for k, v in parts.items()}
        if len(held_out) and (it % cfg.checkpoint_every == 0 or it == cfg.iterations):
            figures = validate(net, held_out)
            score = figures["nll_action"] + figures["nll_grip"]
            log.info("iteration %d: held out, NLL %.3f, action %.2f mm / %.2f° off, gripper right %.3f", it, score,
                     figures["action_error_mm"], figures["action_error_deg"], figures["grip_accuracy"])
            if best is None or score < best[0]:
                best = (score, it, copy.deepcopy(net.state_dict()))
    if best is not None:
        net.load_state_dict(best[2])
        report |= {"checkpoint_iteration": best[1]} | {f"validation_{k}": v for k, v in validate(net, held_out).items()}
    report |= {"episodes": len(train_set), "frames": int(lengths.sum()), "validation_episodes": len(held_out)}
    return BCModel(net.eval(), method, objects, demos.fps), report


def save(model: BCModel, cfg: BCConfig, out_dir: Path) -> None:
    """Weights (safetensors) and ``config.json``, the directory swapped in whole."""
    net = model.net
    with atomic_path(Path(out_dir)) as tmp:
        tmp.mkdir()
        save_file({k: v.contiguous() for k, v in net.state_dict().items()}, tmp / "model.safetensors")
        config = {"format": FORMAT, "method": model.method, "objects": model.objects, "fps": model.fps,
                  "d_obs": int(net.obs_mean.shape[0]), "train": asdict(cfg)}
        (tmp / "config.json").write_text(json.dumps(config, indent=2) + "\n")


def load(model_dir: Path) -> BCModel:
    """A model written by :func:`save`; a one-line error naming the directory otherwise."""
    model_dir = Path(model_dir)
    if not (model_dir / "config.json").is_file() or not (model_dir / "model.safetensors").is_file():
        raise HspError(f"{model_dir}: not a trained bc model (needs config.json and model.safetensors; run `hsp train`)")
    try:
        config = json.loads((model_dir / "config.json").read_text())
        if config.get("format") != FORMAT or config.get("method") not in ("bc", "bc-rnn"):
            raise ValueError(f"model format {config.get('format')} of method {config.get('method')!r}, this hsp reads bc "
                             f"and bc-rnn format {FORMAT}")
        cfg = BCConfig(**config["train"])
        net = GaussianPolicy(config["d_obs"], cfg.hidden, cfg.layers, config["method"] == "bc-rnn")
        net.load_state_dict(load_file(model_dir / "model.safetensors"))
        return BCModel(net.eval(), config["method"], config["objects"], int(config["fps"]))
    except (SafetensorError, ValueError, KeyError, TypeError, RuntimeError, OSError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise HspError(f"{model_dir}: not a trained bc model of this hsp version (retrain with `hsp train`): {first}") from None


class BCAgent:
    """Closed loop: ``reset(poses, seed)``, then ``act(poses) -> (8,)`` per control step with
    the observed world poses ``(n, 7)``; bc-rnn's LSTM state runs over the whole episode."""

    def __init__(self, model: BCModel, task: Task, source: str = "model") -> None:
        if model.objects != task.names:
            raise HspError(f"{source}: a model for objects {model.objects}, not those of task {task.name!r} {task.names}")
        self.model, self.symmetries = model, [o.symmetry for o in task.objects]
        if model.net.obs_mean.shape[0] != POSE_FEATURES * len(task.names):
            raise HspError(f"{source}: observations of {model.net.obs_mean.shape[0]} numbers, task {task.name!r} has "
                           f"{POSE_FEATURES * len(task.names)}")

    def reset(self, poses: np.ndarray, seed: int) -> None:
        self.first = np.asarray(poses, np.float64).copy()
        self.state: tuple[torch.Tensor, torch.Tensor] | None = None

    @torch.no_grad()
    def act(self, poses: np.ndarray) -> np.ndarray:
        world = canonical_poses(np.stack([self.first, poses]), self.symmetries)[1]
        obs = torch.from_numpy(flat_observation(world)).float()[None, None]
        net = self.model.net
        mean, _, logits, self.state = net(obs, self.state)
        return command(net, poses[0], mean[0, 0], logits[0, 0, 0])


def command(net: GaussianPolicy, ee: np.ndarray, mean: torch.Tensor, grip_logit: torch.Tensor) -> np.ndarray:
    """The environment's action ``(8,)``: e_t ``(7,)`` moved by a_t's mean (standardised
    ``(6,)``), the gripper closed when its logit is positive."""
    step = (mean * net.act_std + net.act_mean).double().numpy()
    return np.concatenate([apply_rotvec_delta(ee, step), [GRIP_CLOSED if grip_logit.item() > 0 else 0]])
