"""act and diffusion (LeRobot's policies, state only): they learn the toy reach that an
untrained policy fails, batches are laid out as LeRobot's dataset would, save -> load acts
identically, LeRobot's own configuration errors are one line."""

import numpy as np
import pytest

from hsp.baselines import lerobot_policies as lp
from hsp.errors import HspError
from tests.baselines.test_bc import toy_demonstrations, toy_layout, toy_success_rate

SMALL = {
    "act": {"dim_model": 64, "dim_feedforward": 128, "n_heads": 4, "n_encoder_layers": 1, "n_decoder_layers": 1,
            "n_vae_encoder_layers": 1, "latent_dim": 8, "chunk_size": 5, "n_action_steps": 5, "optimizer_lr": 1e-3, "dropout": 0.0},
    "diffusion": {"down_dims": [16, 32, 64], "n_obs_steps": 2, "horizon": 8, "n_action_steps": 4,
                  "noise_scheduler_type": "DDIM", "num_train_timesteps": 100, "num_inference_steps": 50,
                  "scheduler_warmup_steps": 10, "optimizer_lr": 1e-3, "diffusion_step_embed_dim": 32,
                  "do_mask_loss_for_padding": True},
}


TOY = {"act": (dict(iterations=1000, batch_size=64), 0.8), "diffusion": (dict(iterations=4000, batch_size=128), 0.5)}
"""Budget of the toy test and the success it must reach (measured: ACT 1.0 of 10 layouts in about
40 s; Diffusion 0.7 in about 3 minutes, 0.9 after 8,000 iterations: docs/baselines.md)."""


@pytest.mark.parametrize("method", TOY)
def test_learns_a_toy_reach_that_an_untrained_policy_fails(tasks, method):
    task = tasks["stacking-1"]
    demos = toy_demonstrations(task, 100, seed=0)
    budget, success = TOY[method]
    model, report = lp.train(demos, task.names, method, lp.LeRobotPolicyConfig(
        **budget, policy=SMALL[method], checkpoint_every=250), seed=0)
    untrained, _ = lp.train(demos, task.names, method, lp.LeRobotPolicyConfig(
        iterations=1, policy=SMALL[method], validation_every=0), seed=0)
    held = demos.subset(list(range(4, 100, 5)))
    assert report["validation_episodes"] == 20
    assert report["validation_loss"] < 0.5 * lp.held_out_loss(untrained, held, seed=0)
    assert toy_success_rate(lp.LeRobotAgent(untrained, task), task) == 0.0
    assert toy_success_rate(lp.LeRobotAgent(model, task), task) >= success


def test_batch_clamps_to_the_episode_and_pads_what_lies_beyond_or_was_not_observed(tasks):
    demos = toy_demonstrations(tasks["stacking-1"], 2, seed=0)
    demos.observed[1][3] = False
    cfg = lp.policy_config("diffusion", demos.obs[0].shape[1], SMALL["diffusion"])  # obs t-1, t; actions t-1 … t+6
    b = lp.batch(demos, np.array([[1, 0], [1, 28]]), cfg)
    assert b[lp.ENV].shape == (2, 2, 27) and b[lp.ACTION].shape == (2, 8, 7)  # 4 objects: 9 + 27
    np.testing.assert_array_equal(b[lp.STATE][0, 0], b[lp.STATE][0, 1])  # t-1 clamped to t = 0
    np.testing.assert_allclose(b[lp.STATE][1, 1].numpy(), demos.obs[1][28, :9].astype(np.float32))
    assert b["action_is_pad"][0].tolist() == [True, False, False, False, True, False, False, False]
    assert b["action_is_pad"][1].tolist() == [False, False, False, True, True, True, True, True]  # 30 frames
    act = lp.batch(demos, np.array([[0, 4]]), lp.policy_config("act", 36, SMALL["act"]))
    assert act[lp.ENV].shape == (1, 27) and act[lp.ACTION].shape == (1, 5, 7)


@pytest.mark.parametrize("method", ["act", "diffusion"])
def test_saved_model_acts_identically(tasks, method, tmp_path):
    """Across a chunk: the action queue, and Diffusion's history and sampling noise, carry
    over identically after save -> load."""
    task = tasks["stacking-1"]
    demos = toy_demonstrations(task, 10, seed=0)
    cfg = lp.LeRobotPolicyConfig(iterations=3, batch_size=8, policy=SMALL[method], checkpoint_every=2)
    model, report = lp.train(demos, task.names, method, cfg, seed=0)
    assert report["validation_episodes"] == 2 and report["checkpoint_iteration"] in (2, 3)
    lp.save(model, cfg, tmp_path / "m")
    loaded = lp.load(tmp_path / "m", method)
    world = toy_layout(task, np.random.default_rng(5))
    a, b = lp.LeRobotAgent(model, task), lp.LeRobotAgent(loaded, task)
    a.reset(world, 3), b.reset(world, 3)
    for _ in range(6):
        np.testing.assert_array_equal(a.act(world), b.act(world))
    with pytest.raises(HspError, match="a act model, not diffusion|a diffusion model, not act"):
        lp.load(tmp_path / "m", "diffusion" if method == "act" else "act")


def test_lerobot_configuration_errors_are_one_line():
    with pytest.raises(HspError, match=r"baselines.diffusion.policy: .*"):
        lp.policy_config("diffusion", 36, {"horizon": 12})  # not a multiple of 2^len(down_dims)
    with pytest.raises(HspError, match=r"baselines.act.policy: .*unexpected keyword"):
        lp.policy_config("act", 36, {"chunk": 5})


def test_action_range_is_centred_on_no_step(tasks):
    """Diffusion samples in [-1, 1] and avoids its edges: a_t = 0 must map mid-range, not to
    an edge, even when the demonstrations only ever step one way (down, here)."""
    stats = lp.dataset_stats(toy_demonstrations(tasks["stacking-1"], 10, seed=0))[lp.ACTION]
    np.testing.assert_array_equal(stats["min"], -stats["max"])
    assert (stats["max"] > 0).all()
