import numpy as np

from hsp.geometry import relative
from hsp.tasks.layout import mesh_extent, sample_layout


def test_same_seed_same_layout_and_different_seed_differs(tasks):
    task = tasks["painting"]
    a = sample_layout(task, np.random.default_rng(7))
    b = sample_layout(task, np.random.default_rng(7))
    c = sample_layout(task, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_table_objects_rest_on_the_table_without_overlap(tasks):
    for task in tasks.values():
        for seed in range(20):
            poses = sample_layout(task, np.random.default_rng(seed))
            table = [i for i, o in enumerate(task.objects) if i > 0 and o.place.support == "table"]
            for i in table:
                radius, rest = mesh_extent(task.mesh(i))
                assert abs(poses[i, 2] - rest) < 1e-12
                x, y = task.objects[i].place.x, task.objects[i].place.y
                assert x[0] <= poses[i, 0] <= x[1] and y[0] <= poses[i, 1] <= y[1]
                for j in table:
                    if j > i:
                        rj = mesh_extent(task.mesh(j))[0]
                        assert np.linalg.norm(poses[i, :2] - poses[j, :2]) >= radius + rj


def test_bolts_sit_on_the_wheel(tasks):
    task = tasks["tire-removal"]
    poses = sample_layout(task, np.random.default_rng(0))
    wheel = task.index("wheel")
    for name in ["bolt_1", "bolt_2", "bolt_3", "bolt_4"]:
        i = task.index(name)
        rel = relative(poses[i], poses[wheel])
        np.testing.assert_allclose(rel[:3], task.objects[i].place.xyz, atol=1e-12)
