"""Supervised training of π_h, π_m and π_l on pseudo-labels (the M-step of Algorithm 1).

L = L_pair + L_w + L_action: the negative log-likelihoods of the labelled (tool, target)
pair under π_h, of the way-point w_t under π_m and of the tool's observed step a_t under
π_l (the paper's L_mem and L_ret are not defined in its text and are left out). Batches
are whole episodes, drawn until they hold ``batch_steps`` frames, so the LSTM reads every
history from its start.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from rich.progress import track
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from hsp.errors import HspError
from hsp.fileio import atomic_path
from hsp.policy.features import Steps
from hsp.policy.networks import Hierarchy, Sizes, gaussian_log_prob
from hsp.policy.normalisation import Normalisation

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainConfig:
    iterations: int = 20000
    """Gradient steps (paper: 20,000)."""
    batch_steps: int = 2048
    """Frames per batch (paper: 2,048)."""
    learning_rate: float = 1e-4
    """Adam's step size (paper: 1e-4)."""
    hidden: int = 64
    memory: int = 32
    validation_every: int = 5
    """Every this-many-th episode (the 5th, 10th, …) is held out to validate; 0: none."""


@dataclass
class Policy:
    """The trained hierarchy with what it needs to read new episodes."""

    net: Hierarchy
    norm: Normalisation
    objects: list[str]
    classes: np.ndarray
    """Semantic label index of each object ``(n,)``."""
    n_classes: int


def _batch(episodes: list[Steps], idx: list[int]) -> dict[str, torch.Tensor]:
    """Episodes ``idx`` padded to one length, with a mask of real frames."""
    T = max(len(episodes[i].pair) for i in idx)
    out: dict[str, torch.Tensor] = {}
    for name in ("z", "history", "progress", "pair", "classes", "current", "target_in_tool", "waypoint", "action"):
        arrays = [getattr(episodes[i], name) for i in idx]
        pad = [np.pad(a, [(0, T - len(a))] + [(0, 0)] * (a.ndim - 1)) for a in arrays]
        out[name] = torch.from_numpy(np.stack(pad))
    lengths = torch.tensor([len(episodes[i].pair) for i in idx])
    steps = torch.arange(T)[None]
    out["mask"] = steps < lengths[:, None]
    out["acted"] = steps < (lengths - 1)[:, None]  # the last frame has no step after it
    return out


def losses(net: Hierarchy, norm: Normalisation, b: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Mean negative log-likelihoods of one batch: pair, way-point, action."""
    memory = net.remember(norm.history(b["history"]))
    progress = norm("progress", b["progress"])
    logp = net.pi_h(norm("z", b["z"]), memory, progress)
    pair = -logp.gather(-1, b["pair"][..., None])[..., 0]
    mean, log_std = net.pi_m(b["classes"], norm("current", b["current"]), memory, progress)
    w = -gaussian_log_prob(mean, log_std, norm("waypoint", b["waypoint"]))
    mean, log_std = net.pi_l(norm("target_in_tool", b["target_in_tool"]), norm("waypoint", b["waypoint"]), b["classes"])
    a = -gaussian_log_prob(mean, log_std, norm("action", b["action"]))
    m, acted = b["mask"].float(), b["acted"].float()
    return {"pair": (pair * m).sum() / m.sum(), "waypoint": (w * m).sum() / m.sum(),
            "action": (a * acted).sum() / acted.sum().clamp(min=1.0)}


def split(n_episodes: int, every: int) -> tuple[list[int], list[int]]:
    """Training and validation episode indices: every ``every``-th episode validates
    (none when ``every`` is 0 or fewer than two episodes would train)."""
    held = [i for i in range(n_episodes) if every > 0 and i % every == every - 1]
    if n_episodes - len(held) < 2:
        held = []
    return [i for i in range(n_episodes) if i not in held], held


def validate(policy: Policy, episodes: list[Steps]) -> dict[str, float]:
    """On held-out episodes, with their labelled history: how often π_h's most likely pair
    is the labelled one, and the median distance (mm) of π_m's mean way-point and π_l's mean
    step from the labelled way-point and the observed step."""
    net, norm = policy.net, policy.norm
    with torch.no_grad():
        b = _batch(episodes, list(range(len(episodes))))
        memory = net.remember(norm.history(b["history"]))
        progress = norm("progress", b["progress"])
        pair = net.pi_h(norm("z", b["z"]), memory, progress).argmax(-1)
        w, _ = net.pi_m(b["classes"], norm("current", b["current"]), memory, progress)
        w = w * norm.stats["waypoint.std"] + norm.stats["waypoint.mean"]
        a, _ = net.pi_l(norm("target_in_tool", b["target_in_tool"]), norm("waypoint", b["waypoint"]), b["classes"])
        a = a * norm.stats["action.std"] + norm.stats["action.mean"]
    mask, acted = b["mask"], b["acted"]
    return {"pair_accuracy": float((pair == b["pair"])[mask].float().mean()),
            "waypoint_error_mm": float(1000 * (w - b["waypoint"])[..., :3].norm(dim=-1)[mask].median()),
            "action_error_mm": float(1000 * (a - b["action"])[..., :3].norm(dim=-1)[acted].median())}


def train(episodes: list[Steps], objects: list[str], classes: np.ndarray, n_classes: int, cfg: TrainConfig,
          seed: int) -> tuple[Policy, dict[str, float]]:
    """π_h, π_m, π_l fitted to labelled ``episodes``; returns the policy and the last losses."""
    if not episodes:
        raise HspError("no labelled episodes to train on")
    if cfg.iterations < 1 or cfg.batch_steps < 1:
        raise HspError(f"train: iterations and batch_steps must be ≥ 1, got {cfg.iterations}, {cfg.batch_steps}")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    P = episodes[0].history.shape[1] - 7
    net = Hierarchy(Sizes(P, n_classes, cfg.hidden, cfg.memory))
    norm = Normalisation.fit(episodes)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    lengths = np.array([len(e.pair) for e in episodes])
    last: dict[str, float] = {}
    for _ in track(range(cfg.iterations), description="train π_h, π_m, π_l"):
        order = rng.permutation(len(episodes))
        take = int(np.searchsorted(np.cumsum(lengths[order]), cfg.batch_steps)) + 1
        parts = losses(net, norm, _batch(episodes, list(order[:take])))
        loss = sum(parts.values())
        opt.zero_grad()
        loss.backward()
        opt.step()
        last = {k: v.item() for k, v in parts.items()} | {"total": loss.item()}
    return Policy(net.eval(), norm, objects, classes, n_classes), last


def save(policy: Policy, cfg: TrainConfig, out_dir: Path) -> None:
    """Weights and normalisation (safetensors) and ``config.json``; the directory is
    swapped in whole, so a reader never sees half a model or one from two runs."""
    with atomic_path(Path(out_dir)) as tmp:
        tmp.mkdir()
        tensors = {f"net.{k}": v.contiguous() for k, v in policy.net.state_dict().items()}
        tensors |= {f"norm.{k}": v for k, v in policy.norm.stats.items()}
        save_file(tensors, tmp / "model.safetensors")
        config = {"train": asdict(cfg), "sizes": asdict(policy.net.sizes), "objects": policy.objects,
                  "classes": policy.classes.tolist(), "n_classes": policy.n_classes}
        (tmp / "config.json").write_text(json.dumps(config, indent=2) + "\n")


def load(model_dir: Path) -> Policy:
    """A policy written by :func:`save`; a one-line error naming the directory when it is
    not one, is damaged or was written in another layout."""
    model_dir = Path(model_dir)
    if not (model_dir / "config.json").is_file() or not (model_dir / "model.safetensors").is_file():
        raise HspError(f"{model_dir}: not a trained policy (needs config.json and model.safetensors; run `hsp train`)")
    try:
        config = json.loads((model_dir / "config.json").read_text())
        tensors = load_file(model_dir / "model.safetensors")
        net = Hierarchy(Sizes(**config["sizes"]))
        net.load_state_dict({k[4:]: v for k, v in tensors.items() if k.startswith("net.")})
        norm = Normalisation({k[5:]: v for k, v in tensors.items() if k.startswith("norm.")})
        return Policy(net.eval(), norm, config["objects"], np.array(config["classes"]), config["n_classes"])
    except (SafetensorError, ValueError, KeyError, TypeError, RuntimeError, OSError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise HspError(f"{model_dir}: not a trained policy of this hsp version (retrain with `hsp train`): {first}") from None
