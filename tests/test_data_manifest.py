"""Dataset manifest: round trip, validation with line numbers, atomic writes, images."""

import numpy as np
import pytest

from crossing_assist.data_tools.images import ImageError, load_rgb, save_rgb
from crossing_assist.data_tools.manifest import (
    COLUMNS, ManifestError, Row, format_votes, parse_votes, read_manifest, write_manifest,
)

HEADER = ",".join(COLUMNS)


def _dataset(tmp_path, lines, images=("a.png", "b.png")):
    for name in images:
        save_rgb(tmp_path / name, np.zeros((4, 6, 3), np.uint8))
    (tmp_path / "manifest.csv").write_text("\n".join([HEADER, *lines]) + "\n")
    return tmp_path


def test_round_trip_keeps_every_field(tmp_path):
    rows = [
        Row("a.png", 6, 0.45685, "ptl:john", "train", {6: 3, 7: 1, 0: 1}, ("blocked",)),
        Row("b.png", 0, None, "vid:c03", "val", {}, ("synthetic", "yaw=+10.0")),
    ]
    for r in rows:
        save_rgb(tmp_path / r.image, np.zeros((4, 6, 3), np.uint8))
    write_manifest(tmp_path, rows)
    ds = read_manifest(tmp_path)
    assert ds.rows == tuple(rows)
    np.testing.assert_array_equal(ds.labels(), [6, 0])
    assert ds.far_x()[0] == 0.45685 and np.isnan(ds.far_x()[1])
    assert len(ds.split("val")) == 1 and ds.split("val").rows[0].image == "b.png"
    assert ds.image_path(ds.rows[0]) == tmp_path / "a.png"
    assert "6:3 7:1 unknown:1" in (tmp_path / "manifest.csv").read_text()


@pytest.mark.parametrize("line, message", [
    ("a.png,13,,s,train,,", "line 3: label '13' invalid"),
    ("a.png,6,1.5,s,train,,", "line 3: far_x"),
    ("a.png,unknown,0.5,s,train,,", "line 3: far_x 0.5 given for an unknown label"),
    ("a.png,3,0.5,s,train,,", "line 3: label 3 disagrees with far_x"),
    ("a.png,6,,s,holdout,,", "line 3: split 'holdout' invalid"),
    ("a.png,6,,s,train,6:x,", "line 3: vote '6:x' invalid"),
    ("a.png,6,,,train,,", "line 3: source"),
    ("/abs/a.png,6,,s,train,,", "line 3: image '/abs/a.png' invalid"),
    ("a.png,6,,s,train", "line 3: wrong number of fields"),
    ("b.png,6,,s,train,,", "line 3: duplicate image 'b.png' (first at line 2)"),
    ("c.png,6,,s,train,,", "line 3: image 'c.png' not found"),
])
def test_first_bad_line_is_named(tmp_path, line, message):
    _dataset(tmp_path, ["b.png,7,0.55,s,train,,", line])
    with pytest.raises(ManifestError, match=message.replace("(", r"\(").replace(")", r"\)")):
        read_manifest(tmp_path)


def test_boundary_rounding_is_tolerated(tmp_path):
    # PTL stores far_x to 5 decimals: 0.58333 is the boundary of strips 7 and 8.
    _dataset(tmp_path, ["a.png,8,0.58333,s,train,,", "b.png,7,0.58333,s,train,,"])
    assert list(read_manifest(tmp_path).labels()) == [8, 7]


def test_missing_header_column_and_missing_manifest(tmp_path):
    with pytest.raises(ManifestError, match="no manifest"):
        read_manifest(tmp_path)
    (tmp_path / "manifest.csv").write_text("image,label\n")
    with pytest.raises(ManifestError, match="line 1: header lacks column"):
        read_manifest(tmp_path)


def test_write_rejects_bad_rows_and_leaves_old_manifest(tmp_path):
    good = [Row("a.png", 6, None, "s", "train")]
    write_manifest(tmp_path, good)
    before = (tmp_path / "manifest.csv").read_text()
    with pytest.raises(ManifestError, match="row 1: duplicate image"):
        write_manifest(tmp_path, good + good)
    with pytest.raises(ManifestError, match="row 0"):
        write_manifest(tmp_path, [Row("a.png", 13, None, "s", "train")])
    assert (tmp_path / "manifest.csv").read_text() == before
    assert [p.name for p in tmp_path.iterdir()] == ["manifest.csv"]   # no temp files left


def test_votes_codec():
    assert parse_votes("6:3 7:1 unknown:1") == {6: 3, 7: 1, 0: 1}
    assert format_votes({0: 1, 7: 1, 6: 3}) == "6:3 7:1 unknown:1"
    for bad in ("6:0", "13:1", "6:1 6:2", "six"):
        with pytest.raises(ValueError):
            parse_votes(bad)


def test_load_rgb_keeps_channel_order_and_names_bad_files(tmp_path):
    img = np.zeros((5, 7, 3), np.uint8)
    img[..., 0] = 200  # red
    save_rgb(tmp_path / "r.png", img)
    back = load_rgb(tmp_path / "r.png")
    assert back.shape == (5, 7, 3) and back[0, 0].tolist() == [200, 0, 0]
    (tmp_path / "broken.jpg").write_bytes(b"\xff\xd8\xff garbage")
    with pytest.raises(ImageError, match="broken.jpg"):
        load_rgb(tmp_path / "broken.jpg")
    with pytest.raises(ImageError, match="nope.png: image not found"):
        load_rgb(tmp_path / "nope.png")


def test_imports_stay_light():
    """The package imports nothing heavy; the manifest reader needs no OpenCV; nothing needs torch."""
    import subprocess
    import sys
    code = ("import sys, crossing_assist.data_tools as d; assert 'cv2' not in sys.modules and 'numpy' not in sys.modules;"
            "import crossing_assist.data_tools.manifest; assert 'cv2' not in sys.modules;"
            "import crossing_assist.data_tools.cli, crossing_assist.data_tools.augment, crossing_assist.data_tools.synth,"
            " crossing_assist.data_tools.labels, crossing_assist.data_tools.ptl, crossing_assist.data_tools.stats;"
            "assert 'torch' not in sys.modules and 'matplotlib' not in sys.modules")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
