"""scripts/zoom_photos.py: a zoomed phone's photo cut from a photo, its far point moved exactly."""

import sys
from pathlib import Path

import numpy as np
import pytest

from crossing_assist.data_tools.exif import equivalent_fov, photo_fov
from crossing_assist.errors import UserError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import zoom_photos as zp  # noqa: E402


def test_zoom_photo_keeps_the_middle_and_moves_the_far_point():
    img = np.zeros((300, 400, 3), np.uint8)
    img[:, 250] = 255                                   # a mark at x = 250 / 400
    out, x = zp.zoom_photo(img, 250.5 / 400, 2.0)
    assert out.shape == (150, 200, 3)
    assert x == pytest.approx((250.5 - 100) / 200)
    assert out[:, int(x * 200)].min() == 255            # the mark is where x says
    assert zp.zoom_photo(img, 0.1, 2.0)[1] is None      # out of the middle half: out of view
    assert zp.zoom_photo(img, 0.9, 3.0)[1] is None


def test_the_folder_written_carries_the_zoomed_cameras_fov(tmp_path):
    pytest.importorskip("PIL")
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest

    src = tmp_path / "ds"
    (src / "images").mkdir(parents=True)
    rows = []
    for i, fx in enumerate((0.5, 0.05)):
        save_rgb(src / "images" / f"p{i}.jpg", np.full((60, 80, 3), 90, np.uint8))
        rows.append(Row(f"images/p{i}.jpg", 7 if fx == 0.5 else 1, fx, "ptl:ann", "val", {}, ()))
    write_manifest(src, rows)
    assert zp.main(["--data", str(src), "--zoom", "2", "--out", str(tmp_path / "z")]) == 0
    lines = (tmp_path / "z" / "labels.csv").read_text().splitlines()
    assert len(lines) == 2 and lines[1].startswith("images/p0_zoom2.jpg,val,ann,0.50000,7,0")   # p1 left out
    assert photo_fov(tmp_path / "z" / "images" / "p0_zoom2.jpg", (30, 40)) == pytest.approx(equivalent_fov(52, 4 / 3))


def test_cut_photo_keeps_a_full_side_and_moves_the_far_point():
    img = np.zeros((300, 400, 3), np.uint8)
    img[:, 250] = 255
    out, x = zp.cut_photo(img, 250.5 / 400, 1.0)          # a square: full height, 50 px off each side
    assert out.shape == (300, 300, 3) and x == pytest.approx((250.5 - 50) / 300)
    assert out[:, int(x * 300)].min() == 255
    out, x = zp.cut_photo(img, 250.5 / 400, 16 / 9)       # wider than the photo: full width
    assert out.shape == (225, 400, 3) and x == pytest.approx(250.5 / 400)
    assert zp.cut_photo(img, 0.05, 1.0)[1] is None        # left of the square: out of view


def test_a_cut_keeps_the_cameras_exif_and_is_read_as_a_crop(tmp_path):
    """An editor's square cut of a 26 mm 4:3 photo sees the photo's height (53.1 deg); without the
    recorded size in its EXIF it would be read as a 26 mm square photo (60.9 deg)."""
    pytest.importorskip("PIL")
    from crossing_assist.data_tools.images import inspect_image_file, save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest

    src = tmp_path / "ds"
    (src / "images").mkdir(parents=True)
    save_rgb(src / "images" / "p0.jpg", np.full((60, 80, 3), 90, np.uint8))
    write_manifest(src, [Row("images/p0.jpg", 7, 0.5, "ptl:ann", "val", {}, ())])
    for out, extra, want in (("c", [], 53.1), ("n", ["--no-recorded-size"], 60.9)):
        assert zp.main(["--data", str(src), "--cut", "1:1", "--out", str(tmp_path / out), *extra]) == 0
        image = tmp_path / out / "images" / "p0_cut1x1.jpg"
        size = inspect_image_file(image)[1]
        assert size == (60, 60)
        assert photo_fov(image, size) == pytest.approx(want, abs=0.1)
    with pytest.raises(UserError, match="Invalid --cut 'square'"):
        zp.main(["--data", str(src), "--cut", "square", "--out", str(tmp_path / "bad")])
