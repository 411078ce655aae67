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


def test_what_a_killed_run_left_is_removed_by_the_next(tmp_path):
    """A run killed with -9 cannot clean up its temporary copy; the next run of the stage does,
    and leaves a running process's copy alone."""
    import subprocess

    dead = subprocess.Popen(["true"])
    dead.wait()
    (tmp_path / f".ds.partial-{dead.pid}" / "meta").mkdir(parents=True)
    (tmp_path / ".ds.partial-1").mkdir()  # pid 1 runs
    with atomic_path(tmp_path / "ds") as tmp:
        tmp.mkdir()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".ds.partial-1", "ds"]
