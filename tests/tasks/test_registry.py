import shutil
from pathlib import Path

import pytest
import yaml

from hsp.errors import HspError
from hsp.tasks.registry import list_tasks, load_task
from tests.conftest import PIPELINE, TASKS


def test_the_four_paper_tasks_load(tasks):
    assert list_tasks(PIPELINE) == sorted(TASKS)
    assert tasks["tire-removal"].names == ["wrench", "wheel", "bolt_1", "bolt_2", "bolt_3", "bolt_4"]
    assert tasks["tire-removal"].labels.count("bolt") == 4, "identical objects share a label"
    for task in tasks.values():
        for i in range(len(task.objects)):
            assert task.mesh(i).is_file() and task.urdf(i).is_file()


def test_unknown_task_lists_the_valid_ones():
    with pytest.raises(HspError, match="unknown task 'juggling'.*painting.*stacking-1.*tire-removal"):
        load_task("juggling", PIPELINE)


@pytest.fixture
def scratch_pipeline(tmp_path: Path) -> Path:
    shutil.copytree(PIPELINE, tmp_path / "pipeline")
    return tmp_path / "pipeline"


def _edit(pipeline: Path, name: str, change) -> None:
    path = pipeline / "tasks" / f"{name}.yaml"
    data = yaml.safe_load(path.read_text())
    change(data)
    path.write_text(yaml.safe_dump(data))


def test_missing_field_is_named(scratch_pipeline):
    _edit(scratch_pipeline, "painting", lambda d: d["objects"][1].pop("label"))
    with pytest.raises(HspError, match=r"painting.yaml: objects\.1\.label: Field required"):
        load_task("painting", scratch_pipeline)


def test_bad_value_is_named(scratch_pipeline):
    _edit(scratch_pipeline, "stacking-1", lambda d: d["success"].update(tolerance=-1))
    with pytest.raises(HspError, match=r"stacking-1.yaml: success\.stacking\.tolerance"):
        load_task("stacking-1", scratch_pipeline)


def test_unknown_object_in_success_is_named(scratch_pipeline):
    _edit(scratch_pipeline, "painting", lambda d: d["success"].update(source="pail"))
    with pytest.raises(HspError, match="object 'pail' is not in objects"):
        load_task("painting", scratch_pipeline)


def test_missing_mesh_is_named(scratch_pipeline):
    (scratch_pipeline / "objects" / "bolt.obj").unlink()
    with pytest.raises(HspError, match=r"tire-removal.yaml: objects\.2 \(bolt_1\): model file .*bolt.obj is missing"):
        load_task("tire-removal", scratch_pipeline)


def test_invalid_yaml_is_reported(scratch_pipeline):
    (scratch_pipeline / "tasks" / "painting.yaml").write_text("objects: [unclosed\n")
    with pytest.raises(HspError, match="painting.yaml: invalid YAML"):
        load_task("painting", scratch_pipeline)
