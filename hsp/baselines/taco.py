"""``taco``: Task Decomposition via Temporal Alignment for Control (Shiarlis et al., 2018).

One sub-policy per sketch symbol b, each with an action head π_b(a_t, g_t | o_t) (the
Gaussian and gripper of :class:`~hsp.baselines.common.GaussianPolicy` on the flat observation)
and a stop head π_b(STOP | o_t). A demonstration comes with its sketch τ = (b_1 … b_L),
the sub-tasks in the order they were done, not where each starts or ends. The weak
supervision here is the demonstrator's annotation: each sketch symbol is a (tool, target)
pair named by its objects, and the sketch is the annotation's sequence of pairs with
repeats merged. TACO needs this; the hierarchy does not.

Alignment model. The acting frames t = 1 … T−1 (frame T has no next step) are aligned
to the sketch by ζ: ζ_1 = 1, ζ_t − ζ_{t−1} ∈ {0, 1}, ζ_{T−1} = L. At each t ≥ 2 the
sub-policy ζ_{t−1} reads o_t and stops (ζ_t = ζ_{t−1} + 1) or goes on; after the last
acting frame, b_L stops at o_T:

  P(ρ | τ) = Σ_ζ Π_t π_{ζ_t}(a_t | o_t) · Π_{t≥2} [1 − s_{ζ_{t−1}}(o_t) or s_{ζ_{t−1}}(o_t)] · s_L(o_T),

summed by the forward recursion over α_t(j) = P(a_{1:t}, ζ_t = j):

  α_1(1) = π_{b_1}(a_1 | o_1),
  α_t(j) = π_{b_j}(a_t | o_t) [α_{t−1}(j) (1 − s_{b_j}(o_t)) + α_{t−1}(j−1) s_{b_{j−1}}(o_t)],
  P(ρ | τ) = α_{T−1}(L) s_{b_L}(o_T),

in log space (:func:`log_likelihood`). Training maximises Σ log P(ρ | τ) over whole
episodes; the checkpoint kept is the one with the highest held-out likelihood per frame.
At test time the sketch is the demonstrations' most common one; its sub-policies run in
order, each until its stop head fires (at most one stop per step, none at the first, as the
alignment model has it), the last one until the episode ends (success or the step limit:
the environment, not the policy, ends an episode here). The stop is drawn from
s_{b_j}(o_t) (seeded by the episode), not thresholded: where a demonstrator waits at a
way-point, the frames before the switch look alike and s is spread over them (a few per
cent each), so a threshold of ½ might never be crossed. Actions are the means.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from rich.progress import track
from torch import nn

from hsp.baselines.common import (BaselineConfig, BestCheckpoint, GaussianPolicy, PoseAgent, episode_batch,
                                  frame_nll, load_model, save_model, whole_episodes)
from hsp.baselines.observations import Demonstrations
from hsp.errors import HspError
from hsp.policy.train import split
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)

IMPOSSIBLE = -1e30
"""log α of a sketch position not reachable yet: finite, since the gradient of
logaddexp(−inf, −inf) is NaN and would poison every weight."""


def annotated_sketches(task: Task, poses: list[np.ndarray], dataset_dir: Path,
                       recordings_dir: Path | None) -> list[list[str]]:
    """Per dataset episode of world poses ``(H, n, 7)``, the sketch of the demonstrator's
    annotation in ``recordings_dir`` (TACO's weak supervision), its objects matched to the
    tracker's as the supervised labels are."""
    from hsp.dataset.reader import episode_recordings
    from hsp.policy.stage import annotation_labels

    if recordings_dir is None:
        raise HspError("taco needs the recordings with the demonstrator's annotation for its sketches (--recordings)")
    labels = annotation_labels(task, episode_recordings(dataset_dir, recordings_dir), poses)
    return [sketch_of(lab.tool, lab.target, task.names) for lab in labels]


def sketch_of(tool: np.ndarray, target: np.ndarray, names: list[str]) -> list[str]:
    """The sketch of one annotated episode: its (tool, target) pairs per frame ``(H,)`` in
    order, repeats merged, each named ``tool>target``."""
    pairs = np.stack([tool, target], 1)
    starts = np.flatnonzero(np.r_[True, np.any(pairs[1:] != pairs[:-1], axis=1)])
    return [f"{names[tool[i]]}>{names[target[i]]}" for i in starts]


def log_likelihood(log_act: torch.Tensor, log_stop: torch.Tensor, log_go: torch.Tensor, lengths: torch.Tensor,
                   sketch_lengths: torch.Tensor) -> torch.Tensor:
    """log P(ρ | τ) per episode ``(B,)`` by the forward recursion. Inputs are per episode,
    frame and sketch position ``(B, T, L)``: log π_{b_j}(a_t | o_t), log s_{b_j}(o_t) and
    log(1 − s_{b_j}(o_t)); episode ``b`` has ``lengths[b]`` frames (the last one terminal)
    and a sketch of ``sketch_lengths[b]`` symbols."""
    B, T, L = log_act.shape
    none = torch.full((B, 1), IMPOSSIBLE, dtype=log_act.dtype)
    alpha = torch.cat([log_act[:, 0, :1], none.expand(B, L - 1)], 1)
    alphas = [alpha]
    for t in range(1, T - 1):
        stay = alpha + log_go[:, t]
        enter = torch.cat([none, alpha[:, :-1] + log_stop[:, t, :-1]], 1)
        alpha = log_act[:, t] + torch.logaddexp(stay, enter)
        alphas.append(alpha)
    rows = torch.arange(B)
    last = torch.stack(alphas, 1)[rows, lengths - 2, sketch_lengths - 1]  # α_{T−1}(L)
    return last + log_stop[rows, lengths - 1, sketch_lengths - 1]


class SubPolicies(nn.Module):
    """One :class:`~hsp.baselines.common.GaussianPolicy` per symbol, with a stop logit."""

    def __init__(self, symbols: list[str], d_obs: int, hidden: int, layers: int) -> None:
        super().__init__()
        self.symbols = list(symbols)
        self.policies = nn.ModuleList(GaussianPolicy(d_obs, hidden, layers, recurrent=False, logits=2) for _ in symbols)

    def scores(self, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Per frame and symbol ``(B, T, K)``: log π_k(a_t, g_t | o_t) (the step's term only
        where it was observed), log s_k(o_t) and log(1 − s_k(o_t))."""
        act, stop, go = [], [], []
        for net in self.policies:
            mean, log_std, logits, _ = net(b["obs"])
            nll, bce = frame_nll(net, b, mean, log_std, logits)
            act.append(-(nll + bce))
            stop.append(nn.functional.logsigmoid(logits[..., 1]))
            go.append(nn.functional.logsigmoid(-logits[..., 1]))
        return torch.stack(act, -1), torch.stack(stop, -1), torch.stack(go, -1)


def sketch_indices(sketches: list[list[str]], symbols: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
    """Sketches as symbol indices ``(B, L)`` (padded with 0) and their lengths ``(B,)``."""
    L = max(len(s) for s in sketches)
    idx = torch.tensor([[symbols.index(x) for x in s] + [0] * (L - len(s)) for s in sketches])
    return idx, torch.tensor([len(s) for s in sketches])


def episode_log_likelihood(model: SubPolicies, b: dict[str, torch.Tensor], sketches: list[list[str]]) -> torch.Tensor:
    """log P(ρ | τ) ``(B,)`` of the batch's episodes under their sketches."""
    act, stop, go = model.scores(b)
    idx, sketch_lengths = sketch_indices(sketches, model.symbols)
    pick = lambda x: torch.gather(x, 2, idx[:, None, :].expand(-1, x.shape[1], -1))  # noqa: E731
    return log_likelihood(pick(act), pick(stop), pick(go), b["present"].sum(1), sketch_lengths)


def check_sketches(demos: Demonstrations, sketches: list[list[str]], source: str) -> None:
    if len(sketches) != len(demos):
        raise HspError(f"{source}: {len(sketches)} sketches for {len(demos)} demonstrations")
    for e, (obs, sketch) in enumerate(zip(demos.obs, sketches)):
        if not 1 <= len(sketch) <= len(obs) - 1:
            raise HspError(f"{source}: episode {e}: a sketch of {len(sketch)} sub-tasks does not fit its "
                           f"{len(obs) - 1} acting frames")


@dataclass
class TacoModel:
    net: SubPolicies
    sketch: list[str]
    """The sketch run at test time (the demonstrations' most common)."""
    objects: list[str]
    fps: int


def train(demos: Demonstrations, sketches: list[list[str]], objects: list[str], cfg: BaselineConfig, seed: int,
          source: str = "demonstrations") -> tuple[TacoModel, dict]:
    """Sub-policies fitted to ``demos`` and their ``sketches`` by maximising log P(ρ | τ)."""
    check_sketches(demos, sketches, source)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    symbols = sorted({x for s in sketches for x in s})
    fit_on, held = split(len(demos), cfg.validation_every)
    train_set, held_out = demos.subset(fit_on), demos.subset(held)
    model = SubPolicies(symbols, demos.obs[0].shape[1], cfg.hidden, cfg.layers)
    for net in model.policies:
        net.standardise(train_set)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.learning_rate)
    lengths = np.array([len(o) for o in train_set.obs])
    held_batch = episode_batch(held_out, list(range(len(held_out)))) if held else None
    best = BestCheckpoint()
    report: dict[str, float | int] = {}
    log.info("train taco: %d episodes (%d frames), %d held out, %d symbols, %d distinct sketches", len(train_set),
             lengths.sum(), len(held_out), len(symbols), len({tuple(s) for s in sketches}))
    for it in track(range(1, cfg.iterations + 1), description="train taco"):
        take = whole_episodes(rng, lengths, cfg.batch_steps)
        b = episode_batch(train_set, take)
        loss = -episode_log_likelihood(model, b, [sketches[fit_on[i]] for i in take]).sum() / b["present"].sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
        report = {"loss": loss.item()}
        if held_batch is not None and (it % cfg.checkpoint_every == 0 or it == cfg.iterations):
            with torch.no_grad():
                score = (-episode_log_likelihood(model, held_batch, [sketches[i] for i in held]).sum()
                         / held_batch["present"].sum()).item()
            best.offer(score, it, model)
            if it % (10 * cfg.checkpoint_every) == 0:
                log.info("iteration %d: held out, −log P(ρ | τ) %.3f per frame", it, score)
    if best.restore(model):
        report |= {"checkpoint_iteration": best.iteration, "validation_nll_per_frame": best.score}
    counts = Counter(tuple(s) for s in sketches)
    sketch, n = counts.most_common(1)[0]
    report |= {"episodes": len(train_set), "frames": int(lengths.sum()), "validation_episodes": len(held_out),
               "symbols": len(symbols), "distinct_sketches": len(counts), "test_sketch_length": len(sketch),
               "test_sketch_share": n / len(sketches)}
    return TacoModel(model.eval(), list(sketch), objects, demos.fps), report


def save(model: TacoModel, cfg: BaselineConfig, out_dir: Path) -> None:
    save_model(model.net, {"method": "taco", "symbols": model.net.symbols, "sketch": model.sketch,
                           "objects": model.objects, "fps": model.fps,
                           "d_obs": int(model.net.policies[0].obs_mean.shape[0]), "train": asdict(cfg)}, out_dir)


def load(model_dir: Path, method: str = "taco") -> TacoModel:
    """A model written by :func:`save`."""
    def build(config: dict) -> SubPolicies:
        cfg = BaselineConfig(**config["train"])
        return SubPolicies(config["symbols"], config["d_obs"], cfg.hidden, cfg.layers)

    net, config = load_model(model_dir, method, build)
    return TacoModel(net, config["sketch"], config["objects"], int(config["fps"]))


class TacoAgent(PoseAgent):
    """Closed loop: the test sketch's sub-policies in order. From the second step on, the
    running sub-policy b_j reads o_t and stops with probability s_{b_j}(o_t) (one stop per
    step; b_{j+1} then acts at o_t, as in training); the last runs until the episode ends."""

    def __init__(self, model: TacoModel, task: Task, source: str = "model") -> None:
        super().__init__(model.objects, int(model.net.policies[0].obs_mean.shape[0]), task, source)
        self.model = model
        self.order = [model.net.symbols.index(x) for x in model.sketch]

    def reset(self, poses: np.ndarray, seed: int) -> None:
        super().reset(poses, seed)
        self.j, self.started = 0, False
        self.rng = np.random.default_rng([seed, 2])  # the stop draws, apart from the layout's stream

    @torch.no_grad()
    def act(self, poses: np.ndarray) -> np.ndarray:
        obs = self.observe(poses)
        net = self.model.net.policies[self.order[self.j]]
        mean, _, logits, _ = net(obs)
        if self.started and self.j < len(self.order) - 1 and self.rng.random() < torch.sigmoid(logits[0, 0, 1]).item():
            self.j += 1
            net = self.model.net.policies[self.order[self.j]]
            mean, _, logits, _ = net(obs)
        self.started = True
        return self.command(net, poses[0], mean[0, 0], logits[0, 0, 0])
