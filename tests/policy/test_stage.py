"""The train stage's view of a task."""

from hsp.policy.stage import semantic_classes


def test_identical_objects_share_a_semantic_class(tasks):
    classes, n = semantic_classes(tasks["tire-removal"])
    assert n == 3 and len(set(classes[2:])) == 1 and len(set(classes[:3])) == 3
