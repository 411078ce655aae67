"""Atomic writes: all or nothing, for files and for directories that already exist."""

import pytest

from hsp.fileio import atomic_path


def test_a_directory_replaces_the_previous_one_whole(tmp_path):
    out = tmp_path / "model"
    for run in ("first", "second"):
        with atomic_path(out) as tmp:
            tmp.mkdir()
            (tmp / f"{run}.txt").write_text(run)
    assert sorted(p.name for p in out.iterdir()) == ["second.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model"]  # no partial or old copy left


def test_a_failed_block_keeps_the_previous_artifact(tmp_path):
    out = tmp_path / "labels.json"
    with atomic_path(out) as tmp:
        tmp.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(out) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert out.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["labels.json"]
