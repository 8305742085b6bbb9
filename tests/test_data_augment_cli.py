"""crossing-data augment and split on a small dataset."""

import subprocess
import sys

import numpy as np

from crossing_assist.actions import x_to_bin
from crossing_assist.data_tools.augment import yaw_x
from crossing_assist.data_tools.images import load_rgb, save_rgb
from crossing_assist.data_tools.manifest import Row, read_manifest, write_manifest


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", *map(str, args)],
                          capture_output=True, text=True)


def _dataset(root):
    rows = [Row("a.png", x_to_bin(0.3), 0.3, "vid:a", "train"), Row("b.png", 0, None, "vid:b", "train"),
            Row("c.png", 12, 0.97, "vid:c", "val")]
    for i, r in enumerate(rows):
        img = np.zeros((12, 24, 3), np.uint8)
        img[:, : 6 + i] = 255          # bright on the left
        save_rgb(root / r.image, img)
    write_manifest(root, rows)
    return rows


def test_augment_writes_exact_labels_for_train_only(tmp_path):
    _dataset(tmp_path / "ds")
    proc = _cli("augment", tmp_path / "ds", "--out", tmp_path / "aug", "--yaw", "-10", "10", "--quiet")
    assert proc.returncode == 0, proc.stderr
    ds = read_manifest(tmp_path / "aug")
    assert len(ds) == 3 + 2 * 3                     # originals + (mirror, 2 yaws) for the 2 train rows
    by_flag = {(r.source, r.flags): r for r in ds.rows}
    m = by_flag[("vid:a", ("mirrored",))]
    assert m.label == 13 - x_to_bin(0.3) and abs(m.far_x - 0.7) < 1e-12
    assert load_rgb(ds.image_path(m))[:, -1].mean() > 200      # the bright side moved right
    y = by_flag[("vid:a", ("yaw=+10.0",))]
    assert abs(y.far_x - yaw_x(0.3, 10.0)) < 1e-12 and y.label == x_to_bin(y.far_x)
    assert by_flag[("vid:b", ("yaw=-10.0",))].label == 0
    assert [r.split for r in ds.rows if r.source == "vid:c"] == ["val"]   # val is not augmented


def test_augment_refuses_its_own_input_and_bad_datasets(tmp_path):
    _dataset(tmp_path / "ds")
    proc = _cli("augment", tmp_path / "ds", "--out", tmp_path / "ds")
    assert proc.returncode == 2 and "is the input dataset" in proc.stderr
    (tmp_path / "ds" / "a.png").unlink()
    proc = _cli("augment", tmp_path / "ds", "--out", tmp_path / "aug")
    assert proc.returncode == 2 and "line 2: image 'a.png' not found" in proc.stderr


def test_split_command_reassigns_by_source(tmp_path):
    rows = [Row(f"{s}_{i}.png", 1, None, f"vid:{s}", "train") for s in range(10) for i in range(3)]
    for r in rows:
        save_rgb(tmp_path / r.image, np.zeros((2, 2, 3), np.uint8))
    write_manifest(tmp_path, rows)
    proc = _cli("split", tmp_path, "--val", "0.3", "--seed", "1")
    assert proc.returncode == 0, proc.stderr
    ds = read_manifest(tmp_path)
    assert len(ds.split("val")) == 9 and not set(ds.split("val").sources()) & set(ds.split("train").sources())
