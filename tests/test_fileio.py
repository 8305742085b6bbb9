"""Atomic writes: a failure leaves the old file untouched and no temporary file behind."""

import pytest

from crossing_assist.fileio import atomic_path, atomic_write_text, link_or_copy


def test_atomic_write_replaces_and_keeps_the_suffix(tmp_path):
    target = tmp_path / "sub" / "plot.png"
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent and tmp.suffix == ".png" and tmp != target
        tmp.write_bytes(b"new")
    assert target.read_bytes() == b"new"
    assert [p.name for p in target.parent.iterdir()] == ["plot.png"]
    assert oct(target.stat().st_mode & 0o777) == oct(0o644)


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temp(tmp_path):
    target = tmp_path / "labels.csv"
    atomic_write_text(target, "old\n")
    with pytest.raises(RuntimeError, match="killed"):
        with atomic_path(target) as tmp:
            tmp.write_text("half a fi")
            raise RuntimeError("killed mid-write")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["labels.csv"]


def test_link_or_copy_replaces_an_existing_file(tmp_path):
    src = tmp_path / "a.jpg"
    src.write_bytes(b"image")
    dst = tmp_path / "out" / "a.jpg"
    link_or_copy(src, dst)
    link_or_copy(src, dst)  # again: replaced, not an error
    assert dst.read_bytes() == b"image"
