"""``bc`` and ``bc-rnn``: behavioural cloning of the end-effector's motion.

``bc`` is the paper's BC baseline: π(a_t, g_t | o_t), a Gaussian policy over the action
a_t (mean from an MLP, spread learnt, in units of the data's spread) and a Bernoulli over
the gripper g_t, on the flat observation o_t (:mod:`~hsp.baselines.observations`),
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

import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from rich.progress import track

from hsp.baselines.common import (BaselineConfig, BestCheckpoint, GaussianPolicy, PoseAgent, episode_batch,
                                  frame_nll, load_model, save_model, whole_episodes)
from hsp.baselines.observations import Demonstrations
from hsp.policy.train import split
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)


@dataclass
class BCModel:
    net: GaussianPolicy
    method: str
    objects: list[str]
    fps: int


def _frames(b: dict[str, torch.Tensor], rows: np.ndarray) -> dict[str, torch.Tensor]:
    """The frames ``rows`` of a batch flattened over episodes, as a batch of one-frame episodes."""
    return {k: v.reshape((-1,) + v.shape[2:])[torch.from_numpy(rows)][:, None] for k, v in b.items()}


def losses(net: GaussianPolicy, b: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """−log π(a_t) over frames whose step was observed and −log π(g_t) over every frame."""
    mean, log_std, logits, _ = net(b["obs"])
    nll, bce = frame_nll(net, b, mean, log_std, logits)
    observed, present = b["observed"], b["present"]
    return {"action": nll.sum() / observed.sum().clamp(min=1),
            "grip": (bce * present).sum() / present.sum().clamp(min=1)}


@torch.no_grad()
def validate(net: GaussianPolicy, demos: Demonstrations) -> dict[str, float]:
    """Held-out figures: the loss terms, the mean action's error (mm, and degrees of turn) on
    observed steps, and how often the gripper is right."""
    training = net.training
    net.eval()
    b = episode_batch(demos, list(range(len(demos))))
    mean, log_std, logits, _ = net(b["obs"])
    nll, bce = frame_nll(net, b, mean, log_std, logits)
    pred = mean * net.act_std + net.act_mean
    observed, present = b["observed"], b["present"]
    err_mm = 1000 * (pred[..., :3] - b["action"][..., :3]).norm(dim=-1)
    err_deg = torch.rad2deg((pred[..., 3:] - b["action"][..., 3:]).norm(dim=-1))
    grip_right = ((logits[..., 0] > 0) == b["grip"]).float()
    net.train(training)
    return {"nll_action": (nll.sum() / observed.sum().clamp(min=1)).item(), "nll_grip": bce[present].mean().item(),
            "action_error_mm": (err_mm[observed].mean()).item(), "action_error_deg": (err_deg[observed].mean()).item(),
            "grip_accuracy": (grip_right[present].mean()).item()}


def train(demos: Demonstrations, objects: list[str], method: str, cfg: BaselineConfig, seed: int
          ) -> tuple[BCModel, dict]:
    """π fitted to ``demos`` by maximum likelihood (``method``: ``bc`` or ``bc-rnn``); the
    model and a report (last losses, held-out figures of the checkpoint kept)."""
    recurrent = method == "bc-rnn"
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    fit_on, held = split(len(demos), cfg.validation_every)
    train_set, held_out = demos.subset(fit_on), demos.subset(held)
    net = GaussianPolicy(demos.obs[0].shape[1], cfg.hidden, cfg.layers, recurrent)
    net.standardise(train_set)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    lengths = np.array([len(o) for o in train_set.obs])
    whole = episode_batch(train_set, list(range(len(train_set))))
    frames = np.flatnonzero(whole["present"].reshape(-1).numpy())
    best = BestCheckpoint()
    report: dict[str, float | int] = {}
    log.info("train %s: %d episodes (%d frames), %d held out to validate", method, len(train_set), lengths.sum(),
             len(held_out))
    for it in track(range(1, cfg.iterations + 1), description=f"train {method}"):
        if recurrent:
            b = episode_batch(train_set, whole_episodes(rng, lengths, cfg.batch_steps))
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
            best.offer(figures["nll_action"] + figures["nll_grip"], it, net)
            if it % (10 * cfg.checkpoint_every) == 0:
                log.info("iteration %d: held out, NLL %.3f, action %.2f mm / %.2f° off, gripper right %.3f", it,
                         figures["nll_action"] + figures["nll_grip"], figures["action_error_mm"],
                         figures["action_error_deg"], figures["grip_accuracy"])
    if best.restore(net):
        report |= {"checkpoint_iteration": best.iteration}
        report |= {f"validation_{k}": v for k, v in validate(net, held_out).items()}
    report |= {"episodes": len(train_set), "frames": int(lengths.sum()), "validation_episodes": len(held_out)}
    return BCModel(net.eval(), method, objects, demos.fps), report


def save(model: BCModel, cfg: BaselineConfig, out_dir: Path) -> None:
    save_model(model.net, {"method": model.method, "objects": model.objects, "fps": model.fps,
                           "d_obs": int(model.net.obs_mean.shape[0]), "train": asdict(cfg)}, out_dir)


def load(model_dir: Path, method: str) -> BCModel:
    """A ``method`` (bc or bc-rnn) model written by :func:`save`."""
    def build(config: dict) -> GaussianPolicy:
        cfg = BaselineConfig(**config["train"])
        return GaussianPolicy(config["d_obs"], cfg.hidden, cfg.layers, recurrent=method == "bc-rnn")

    net, config = load_model(model_dir, method, build)
    return BCModel(net, method, config["objects"], int(config["fps"]))


class BCAgent(PoseAgent):
    """Closed loop; bc-rnn's LSTM state runs over the whole episode."""

    def __init__(self, model: BCModel, task: Task, source: str = "model") -> None:
        super().__init__(model.objects, int(model.net.obs_mean.shape[0]), task, source)
        self.model = model

    def reset(self, poses: np.ndarray, seed: int) -> None:
        super().reset(poses, seed)
        self.state: tuple[torch.Tensor, torch.Tensor] | None = None

    @torch.no_grad()
    def act(self, poses: np.ndarray) -> np.ndarray:
        mean, _, logits, self.state = self.model.net(self.observe(poses), self.state)
        return self.command(self.model.net, poses[0], mean[0, 0], logits[0, 0, 0])
