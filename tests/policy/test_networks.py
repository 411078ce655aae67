"""The networks' inputs (hsp/policy/networks.py)."""

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from hsp.geometry import compose, relative
from hsp.policy.features import FLAGS
from hsp.policy.networks import Hierarchy, Sizes, upright
from hsp.policy.normalisation import Normalisation
from tests.policy.test_features import _steps


def _scene(rng: np.random.Generator, n: int = 3) -> np.ndarray:
    """World poses ``(n, 7)`` of objects tilted a little, anywhere on a table."""
    tilt = Rotation.from_euler("xyz", np.c_[rng.normal(0, 0.2, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    return np.c_[rng.uniform([0.3, -0.3, 0.0], [0.7, 0.3, 0.3], (n, 3)), tilt.as_quat()]


def test_pi_h_reads_the_same_scene_wherever_it_lies_and_however_it_is_turned_on_the_table():
    """Moving and turning the whole scene about the vertical changes no input of π_h (what
    comes next does not depend on where the layout lies), while raising or tilting an
    object does."""
    rng = np.random.default_rng(0)
    torch.manual_seed(0)
    net = Hierarchy(Sizes(3, 2))
    norm = Normalisation.fit([_steps()[2]])
    codes = torch.eye(2)[[0, 1, 1]]

    def read(world: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        ee_in = relative(np.repeat(world[:1], len(world), 0), world)
        f = lambda x: torch.as_tensor(np.asarray(x, np.float32))  # noqa: E731
        return net.read(norm, codes, f(world), f(ee_in), torch.zeros(3, FLAGS), torch.ones(3, dtype=torch.bool),
                        torch.zeros(7), torch.zeros(4), torch.zeros(net.sizes.memory))

    world = _scene(rng)
    move = np.r_[0.2, -0.1, 0.0, Rotation.from_euler("z", 1.1).as_quat()]
    moved = compose(np.broadcast_to(move, world.shape), world)
    for a, b in zip(read(world), read(moved)):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
    raised, tilted = world.copy(), world.copy()
    raised[1, 2] += 0.04
    tilted[1, 3:] = (Rotation.from_euler("x", 0.5) * Rotation.from_quat(world[1, 3:])).as_quat()
    for changed in (raised, tilted):
        assert not torch.allclose(read(world)[0][1], read(changed)[0][1], atol=1e-3)


def test_upright_is_the_height_and_the_cosine_of_the_tilt():
    rng = np.random.default_rng(1)
    world = _scene(rng, 5)
    out = upright(torch.as_tensor(world)).numpy()
    np.testing.assert_allclose(out[:, 0], world[:, 2])
    np.testing.assert_allclose(out[:, 1], Rotation.from_quat(world[:, 3:]).as_matrix()[:, 2, 2], atol=1e-12)
