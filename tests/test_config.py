from pathlib import Path

import pytest

from hsp.config import load_params, section
from hsp.errors import HspError
from hsp.perception.tracker import TrackerConfig


def test_the_params_file_spells_out_the_tracker_defaults():
    """params.yaml states every tracker knob it lists at its default, nested sections included."""
    params = load_params(Path(__file__).parents[1] / "params.yaml")
    cfg = section(params, "tracker", TrackerConfig)
    assert cfg == TrackerConfig()
    assert set(params["tracker"]["rest"]) and set(params["tracker"]["edges"])


def test_the_params_file_states_every_training_knob_at_its_default():
    from hsp.policy.train import TrainConfig

    params = load_params(Path(__file__).parents[1] / "params.yaml")
    assert section(params, "train", TrainConfig) == TrainConfig()
    assert set(params["train"]) == set(TrainConfig.__dataclass_fields__)


def test_nested_sections_override_one_knob_and_name_unknown_keys():
    cfg = section({"tracker": {"rest": {"rest_frames": 4}, "edges": {"samples": 3}}}, "tracker", TrackerConfig)
    assert cfg.rest.rest_frames == 4 and cfg.rest.still_m == TrackerConfig().rest.still_m
    assert cfg.edges.samples == 3
    with pytest.raises(HspError, match=r"tracker\.rest: unknown keys \['stil_m'\]"):
        section({"tracker": {"rest": {"stil_m": 0.1}}}, "tracker", TrackerConfig)
    with pytest.raises(HspError, match=r"tracker\.edges: expected a mapping"):
        section({"tracker": {"edges": 3}}, "tracker", TrackerConfig)
