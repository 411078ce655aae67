"""The label stage's parquet: written and read back, checked against the dataset's episodes."""

import numpy as np
import pytest

from hsp.errors import HspError
from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig
from hsp.labeling.stage import labels_frame, read_labels
from tests.labeling.test_em import _episode


@pytest.fixture
def labels_file(tmp_path):
    world, status = _episode(H=30)
    labels = [label_episode(world, status, PriorConfig())] * 2
    path = tmp_path / "labels.parquet"
    labels_frame(labels).to_parquet(path)
    return path, labels


def test_labels_read_back_as_written(labels_file):
    path, labels = labels_file
    back = read_labels(path, [30, 30], 3)
    hand = labels[0].tool == 0
    assert labels[0].equivalent[hand, 1:].all(), "the two still objects cannot be told apart"
    for a, b in zip(back, labels):
        np.testing.assert_array_equal(a.target, b.target)
        np.testing.assert_array_equal(a.waypoint_index, b.waypoint_index)
        np.testing.assert_allclose(a.waypoint, b.waypoint)
        np.testing.assert_array_equal(a.equivalent, b.equivalent)


@pytest.mark.parametrize("lengths, n, match", [([30], 3, "the dataset has 1 episodes"),
                                               ([30, 31], 3, "episode 1 has 30 labelled frames"),
                                               ([30, 30], 2, "beyond the dataset's 2")])
def test_labels_of_another_dataset_are_a_clear_error(labels_file, lengths, n, match):
    with pytest.raises(HspError, match=match):
        read_labels(labels_file[0], lengths, n)
