"""Field views (issue 13): crop_window / portrait_views label arithmetic, roll, field_view,
corruptions; negatives cut above the far kerb; load_frame (aspect flag, EXIF orientation)."""

import subprocess
import sys

import cv2
import numpy as np
import pytest

from crossing_assist.actions import UNKNOWN, bin_center_x, x_to_bin
from crossing_assist.data_tools.augment import crop_window, field_view, magnify, portrait_views, roll
from crossing_assist.data_tools.corrupt import CORRUPTIONS, corrupt
from crossing_assist.data_tools.images import ImageError, flag_value, load_frame, load_rgb, save_rgb, true_aspect
from crossing_assist.data_tools.manifest import Row, read_manifest, write_manifest

H, W = 120, 160                                         # a 4:3 landscape photo


def _photo(seed=0):
    return np.random.default_rng(seed).integers(0, 256, (H, W, 3), dtype=np.uint8)


# ----------------------------------------------------------------------------- crop_window

@pytest.mark.parametrize("far_x, offset", [(0.5, 0.5), (0.3, 0.5), (0.1, 0.0), (0.9, 1.0), (0.6, 0.25)])
def test_crop_window_moves_the_goal_exactly(far_x, offset):
    img = _photo()
    win, x, b = crop_window(img, far_x, x_to_bin(far_x), 3 / 4, offset)
    cw = round(3 / 4 * H)                                # 90 px wide, full height
    x0 = round(offset * (W - cw))
    np.testing.assert_array_equal(win, img[:, x0:x0 + cw])
    assert x == pytest.approx((far_x * W - x0) / cw) and b == x_to_bin(x)


def test_crop_window_out_of_view_goes_to_the_edge_strip_and_wide_keeps_x():
    img = _photo()
    _, x, b = crop_window(img, 0.05, 1, 3 / 4, 1.0)      # window x0 = 70 px; goal at 8 px: left of it
    assert b == 1 and 0 < x < 1 / 12
    _, x, b = crop_window(img, 0.97, 12, 3 / 4, 0.0)     # window 0..90 px; goal at 155 px: right of it
    assert b == 12 and 11 / 12 < x < 1
    win, x, b = crop_window(img, 0.3, 4, 16 / 9, 0.3)    # wider: full width, the middle rows
    assert win.shape == (round(W / (16 / 9)), W, 3) and x == 0.3 and b == 4
    np.testing.assert_array_equal(win, img[15:105])
    _, x, b = crop_window(img, None, 6, 3 / 4, 0.5)      # a voted bin without far_x: its centre moves
    assert x == pytest.approx((bin_center_x(6) * W - 35) / 90) and b == x_to_bin(x)
    _, x, b = crop_window(img, None, UNKNOWN, 3 / 4, 0.5)
    assert x is None and b == UNKNOWN


def test_portrait_views_spread_left_to_right_with_in_view_flags():
    img = _photo()
    views = portrait_views(img, 0.1, x_to_bin(0.1), n=3)
    assert [v[0].shape for v in views] == [(H, 90, 3)] * 3
    np.testing.assert_array_equal(views[0][0], img[:, :90])
    np.testing.assert_array_equal(views[2][0], img[:, 70:])
    (_, x0, b0, in0), (_, x1, b1, in1), (_, x2, b2, in2) = views
    assert in0 and x0 == pytest.approx(16 / 90) and b0 == x_to_bin(16 / 90)      # goal at 16 px
    assert not in1 and x1 is None and b1 == 1                                     # x0 = 35 px
    assert not in2 and x2 is None and b2 == 1
    views = portrait_views(img, None, UNKNOWN, n=2)
    assert all(v[1] is None and v[2] == UNKNOWN and not v[3] for v in views)
    # a voted strip without far_x (crossing-data votes): its centre decides "in view", no x
    voted = portrait_views(img, None, 2, n=3)
    assert [(v[1], v[2], v[3]) for v in voted] == [(None, x_to_bin(bin_center_x(2) * W / 90), True),
                                                    (None, 1, False), (None, 1, False)]


# ----------------------------------------------------------------------------- roll

def _dot_image(fx, fy):
    img = np.zeros((H, W, 3), np.uint8)
    cv2.circle(img, (int(fx * W), int(fy * H)), 3, (255, 255, 255), -1)
    return img


@pytest.mark.parametrize("deg", [0.0, 10.0, -15.0, 30.0])
def test_roll_moves_the_goal_as_the_rotation_does(deg):
    fx, fy = 0.7, 0.7
    img = _dot_image(fx, fy)
    out, x, b = roll(img, fx, fy, x_to_bin(fx), deg)
    assert out.shape == img.shape and out.dtype == np.uint8
    ys, xs = np.nonzero(out[..., 0] > 128)
    seen = (xs.mean() + 0.5) / W                           # where the dot is in the rolled frame
    assert x == pytest.approx(seen, abs=1.5 / W) and b == x_to_bin(x)
    if deg == 0:
        assert x == pytest.approx(fx, abs=1e-6)
    if deg > 0:                                            # counter-clockwise: a low-right goal moves right
        assert x > fx


def test_roll_fills_the_uncovered_corners_with_the_pad_and_never_shows_the_goal_twice():
    """Reflected corners could mirror a goal near a side edge into the corner (a second goal, one
    strip away from the label); the runtime levels with the pad colour, so training rolls do too."""
    from crossing_assist.geometry import PAD_RGB

    fx, fy = 0.96, 0.3
    out, x, b = roll(_dot_image(fx, fy), fx, fy, x_to_bin(fx), 15.0)
    n, _ = cv2.connectedComponents((out[..., 0] > 200).astype(np.uint8))
    assert n - 1 == 1                                        # one bright dot: the goal, once
    np.testing.assert_array_equal(out[0, 0], PAD_RGB)          # a corner the camera did not see
    np.testing.assert_array_equal(out[-1, -1], PAD_RGB)
    ys, xs = np.nonzero(out[..., 0] > 200)
    assert x == pytest.approx((xs.mean() + 0.5) / W, abs=1.5 / W) and b == x_to_bin(x)
    # a script simulating a rolled camera asks for the scene reflected in (no pad corners)
    seen, x2, _ = roll(_photo(), fx, fy, x_to_bin(fx), 15.0, fill="reflect")
    assert x2 == x and not (seen[0, 0] == PAD_RGB).all()
    with pytest.raises(ValueError, match="fill"):
        roll(_photo(), fx, fy, x_to_bin(fx), 15.0, fill="mirror")


def test_roll_out_of_frame_goes_to_the_edge_and_unknown_stays_unknown():
    img = _photo()
    _, x, b = roll(img, 0.98, 0.98, 12, 20.0)
    assert b == 12 and x < 1
    out, x, b = roll(img, None, 0.5, UNKNOWN, 10.0)
    assert x is None and b == UNKNOWN and not np.array_equal(out, img)


# ----------------------------------------------------------------------------- field_view, corruptions

def test_field_view_is_deterministic_for_a_seeded_rng_and_varies_across_seeds():
    img = _photo()
    a = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(7))
    b = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(7))
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1:] == b[1:]
    tags = {field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s))[3] for s in range(12)}
    assert len(tags) > 3
    for s in range(12):
        v, x, lab, tag = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s))
        assert v.dtype == np.uint8 and v.ndim == 3 and 1 <= lab <= 12 and lab == x_to_bin(x)


def test_field_view_without_a_step_leaves_only_that_step_out():
    """An ablation's views (``without``) differ from the full recipe's only in the step left out:
    every other draw stays the same, so the two recipes see the same rolls, aspects and corruptions."""
    img = _photo()
    for s in range(16):
        full = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s))
        tags = full[3].split()
        no_corr = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s), ("corruption",))
        assert no_corr[3].split() == [t for t in tags if t not in CORRUPTIONS]
        no_roll = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s), ("roll",))
        assert no_roll[3].split() == [t for t in tags if not t.startswith("roll=")]
        no_aspect = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s), ("aspect",))
        assert no_aspect[0].shape[1] / no_aspect[0].shape[0] == pytest.approx(img.shape[1] / img.shape[0], abs=0.02)
        if not any(t in CORRUPTIONS for t in tags):   # nothing left out: the very same view
            np.testing.assert_array_equal(no_corr[0], full[0])
            assert no_corr[1:] == full[1:]
        one = next((t for t in tags if t in CORRUPTIONS), None)
        if one:   # one corruption by name: only that one goes
            assert one not in field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s), (one,))[3].split()


@pytest.mark.parametrize("far_x, scale, xo, yo", [(0.5, 1.5, 0.5, 0.5), (0.3, 1.25, 0.0, 0.25), (0.9, 1.7, 1.0, 0.75)])
def test_magnify_keeps_the_aspect_and_moves_the_goal_exactly(far_x, scale, xo, yo):
    img = _photo()
    win, x, b = magnify(img, far_x, x_to_bin(far_x), scale, xo, yo)
    cw, ch = round(W / scale), round(H / scale)
    x0, y0 = round(xo * (W - cw)), round(yo * (H - ch))
    np.testing.assert_array_equal(win, img[y0:y0 + ch, x0:x0 + cw])
    assert x == pytest.approx(min(max((far_x * W - x0) / cw, 1e-6), 1 - 1e-6)) and b == x_to_bin(x)


def test_magnify_out_of_view_goes_to_the_edge_strip_and_refuses_shrinking():
    img = _photo()
    _, x, b = magnify(img, 0.02, 1, 1.6, 1.0)            # window from 60 px; goal at 3 px: left of it
    assert b == 1 and 0 < x < 1 / 12
    _, x, b = magnify(img, 0.98, 12, 1.6, 0.0)           # window 0..100 px; goal at 157 px: right of it
    assert b == 12 and 11 / 12 < x < 1
    _, x, b = magnify(img, None, UNKNOWN, 1.5, 0.5)
    assert x is None and b == UNKNOWN
    with pytest.raises(ValueError, match="magnification"):
        magnify(img, 0.5, 7, 0.8, 0.5)


def test_field_view_zoom_magnifies_some_views_and_without_it_the_recipe_is_unchanged():
    """``zoom`` = 1 draws nothing more (so the default recipe's views stay what they were); with a
    zoom, the mirror, roll and aspect drawn are the zoomless ones, and some views are magnified by
    at most it (a window of the same aspect)."""
    img = _photo()
    geometric = lambda tag: [t for t in tag.split() if t == "m" or t.startswith(("roll=", "aspect="))]  # noqa: E731
    zoomed = 0
    for s in range(24):
        plain = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s))
        again = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s), zoom=1.0)
        np.testing.assert_array_equal(plain[0], again[0])
        z = field_view(img, 0.4, 0.6, x_to_bin(0.4), np.random.default_rng(s), zoom=1.7)
        assert geometric(z[3]) == geometric(plain[3])
        scale = [float(t[5:]) for t in z[3].split() if t.startswith("zoom=")]
        if scale:
            zoomed += 1
            assert 1.0 <= scale[0] <= 1.7
            assert z[0].shape[1] == pytest.approx(plain[0].shape[1] / scale[0], abs=1)
            assert z[0].shape[1] / z[0].shape[0] == pytest.approx(plain[0].shape[1] / plain[0].shape[0], rel=0.03)
            assert 1 <= z[2] <= 12 and z[2] == x_to_bin(z[1])
    assert 4 <= zoomed <= 20


def test_field_view_keeps_unknown_unknown():
    img = _photo()
    for s in range(20):
        _, x, lab, _ = field_view(img, None, 0.5, UNKNOWN, np.random.default_rng(s))
        assert x is None and lab == UNKNOWN


@pytest.mark.parametrize("name", sorted(CORRUPTIONS))
def test_corruptions_keep_shape_and_dtype_and_change_pixels(name):
    img = cv2.GaussianBlur(_photo(), (5, 5), 0)   # some structure, mid-range values
    out = corrupt(img, name, np.random.default_rng(1))
    assert out.shape == img.shape and out.dtype == np.uint8
    assert np.abs(out.astype(int) - img.astype(int)).mean() > 0.5
    again = corrupt(img, name, np.random.default_rng(1))
    np.testing.assert_array_equal(out, again)                  # the rng decides everything


def test_unknown_corruption_is_refused():
    with pytest.raises(ValueError, match="Unknown corruption"):
        corrupt(_photo(), "fog", np.random.default_rng(0))


# ----------------------------------------------------------------------------- images

def test_load_frame_undoes_the_aspect_flag(tmp_path):
    img = np.zeros((60, 60, 3), np.uint8)
    img[:, 15] = 255                                       # a bar at x = 0.25 of a squashed 4:3 photo
    save_rgb(tmp_path / "sq.png", img)
    out = load_frame(tmp_path / "sq.png", ("aspect=4:3", "far_y=0.5"))
    assert out.shape == (60, 80, 3)
    assert abs(np.argmax(out[30, :, 0]) / 80 - 15 / 60) < 2 / 80
    assert load_frame(tmp_path / "sq.png").shape == (60, 60, 3)
    assert true_aspect(out, ("aspect=4:3",)) is out                 # already 4:3: untouched
    assert flag_value(("blocked", "far_y=0.41"), "far_y") == "0.41" and flag_value(("x",), "far_y") is None
    with pytest.raises(ValueError, match="aspect"):
        true_aspect(img, ("aspect=wide",))


def test_load_frame_applies_exif_orientation(tmp_path):
    from PIL import Image

    img = np.zeros((40, 80, 3), np.uint8)                   # stored 80 wide x 40 high
    img[:, :10] = (255, 0, 0)                              # red on the stored left edge
    exif = Image.Exif()
    exif[0x0112] = 6                                       # rotate 90 CW to display
    Image.fromarray(img).save(tmp_path / "r.jpg", quality=95, exif=exif)
    out = load_frame(tmp_path / "r.jpg")
    assert out.shape == (80, 40, 3)                        # displayed portrait
    assert out[:8, :, 0].mean() > 200 and out[-8:, :, 0].mean() < 60   # stored left -> displayed top
    assert load_rgb(tmp_path / "r.jpg").shape == (80, 40, 3)


def test_heic_phone_photos_are_read_upright_and_truncated_ones_refused(tmp_path):
    """An iPhone-style HEIC (the turn in the container's irot box and in EXIF, as iOS writes
    both): read as displayed, turned once, not twice; a cut file is named as unreadable."""
    pillow_heif = pytest.importorskip("pillow_heif")
    from PIL import Image

    from crossing_assist.data_tools.images import check_image_file, inspect_image_file

    pillow_heif.register_heif_opener()
    img = np.zeros((40, 80, 3), np.uint8)                   # stored 80 wide x 40 high
    img[:, :10] = (255, 0, 0)                              # red on the stored left edge
    exif = Image.Exif()
    exif[0x0112] = 6                                       # rotate 90 CW to display
    Image.fromarray(img).save(tmp_path / "r.heic", quality=95, exif=exif.tobytes())   # pillow-heif writes irot from it
    out = load_frame(tmp_path / "r.heic")
    assert out.shape == (80, 40, 3) and out.dtype == np.uint8          # displayed portrait
    root = out
    while isinstance(root.base, np.ndarray):
        root = root.base
    assert root.flags.owndata    # numpy's own pixels: a view into libheif's buffer was freed under it (a crash)
    assert out[:8, :, 0].mean() > 200 and out[-8:, :, 0].mean() < 60   # stored left -> displayed top
    assert inspect_image_file(tmp_path / "r.heic") == (None, (80, 40))
    data = (tmp_path / "r.heic").read_bytes()
    (tmp_path / "cut.heic").write_bytes(data[: len(data) * 2 // 3])
    assert "not a readable image" in check_image_file(tmp_path / "cut.heic")
    with pytest.raises(ImageError, match="cut.heic: not a readable HEIC/HEIF image"):
        load_rgb(tmp_path / "cut.heic")


def test_avif_photos_are_read_upright(tmp_path):
    """OpenCV decodes AVIF but ignores its rotation box; Pillow reads the turn."""
    from PIL import Image, features

    if not features.check("avif"):
        pytest.skip("this Pillow has no AVIF support")
    img = np.zeros((40, 80, 3), np.uint8)
    img[:, :10] = (255, 0, 0)                              # red on the stored left edge
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(img).save(tmp_path / "r.avif", quality=95, exif=exif.tobytes())
    out = load_rgb(tmp_path / "r.avif")
    assert out.shape == (80, 40, 3) and out[:8, :, 0].mean() > 200 and out[-8:, :, 0].mean() < 60
    data = (tmp_path / "r.avif").read_bytes()
    (tmp_path / "cut.avif").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageError, match="cut.avif"):
        load_rgb(tmp_path / "cut.avif")


def test_heic_without_pillow_heif_says_what_to_install(tmp_path, monkeypatch):
    (tmp_path / "x.heic").write_bytes(b"\0\0\0\x18ftypheic\0\0\0\0mif1heic" + bytes(64))
    monkeypatch.setitem(sys.modules, "pillow_heif", None)   # as if not installed
    with pytest.raises(ImageError, match=r"x.heic: a HEIC/HEIF photo; reading it needs pillow-heif \(pip install"):
        load_rgb(tmp_path / "x.heic")


# ----------------------------------------------------------------------------- negatives

def _cli(*args):
    return subprocess.run([sys.executable, "-m", "crossing_assist.data_tools.cli", *map(str, args)],
                          capture_output=True, text=True)


def _kerb_dataset(root, with_far_y=True):
    """Photos red above the far kerb (far_y = 0.7) and green below it."""
    rows = []
    for i in range(6):
        img = np.zeros((H, W, 3), np.uint8)
        img[:int(0.7 * H)] = (200, 30, 30)
        img[int(0.7 * H):] = (30, 200, 30)
        save_rgb(root / "images" / f"p{i}.png", img)
        flags = ("far_y=0.7000",) if with_far_y else ()
        label, fx = (UNKNOWN, None) if i == 5 else (i + 3, bin_center_x(i + 3))
        rows.append(Row(f"images/p{i}.png", label, fx, f"src:{i % 2}", "train" if i < 4 else "val", {}, flags))
    write_manifest(root, rows)
    return root


def test_negatives_writes_unknown_views_above_the_kerb_with_source_and_split(tmp_path):
    ds = _kerb_dataset(tmp_path / "ds")
    r = _cli("negatives", ds, "--out", tmp_path / "neg", "--quiet")
    assert r.returncode == 0, r.stderr
    neg = read_manifest(tmp_path / "neg")
    src = {row.image: row for row in read_manifest(ds).rows if row.label != UNKNOWN}
    assert len(neg.rows) == len(src) == 5                   # the unknown photo gives none
    for row in neg.rows:
        assert row.label == UNKNOWN and row.far_x is None
        parent = next(s for name, s in src.items() if f"{name.split('/')[-1][:-4]}_" in row.image)
        assert (row.source, row.split) == (parent.source, parent.split)
        crop = load_rgb(neg.image_path(row))
        h, w = crop.shape[:2]
        assert max(h, w) / min(h, w) == pytest.approx(4 / 3, abs=0.05)
        assert crop[..., 1].mean() < 60 and crop[..., 0].mean() > 150      # all above the kerb
    _cli("negatives", ds, "--out", tmp_path / "neg2", "--quiet")
    assert sorted(x.image for x in read_manifest(tmp_path / "neg2").rows) == sorted(x.image for x in neg.rows)


def test_negatives_refuses_a_dataset_without_far_y(tmp_path):
    ds = _kerb_dataset(tmp_path / "ds", with_far_y=False)
    r = _cli("negatives", ds, "--out", tmp_path / "neg")
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "far_y" in lines[0], r.stderr
    assert not (tmp_path / "neg" / "manifest.csv").exists()


def test_import_ptl_keeps_far_y_and_negatives_follow(tmp_path):
    ptl = tmp_path / "ptl"
    (ptl / "images").mkdir(parents=True)
    lines = ["image,split,photographer,far_x,far_y,near_x,near_y,bin12,light,blocked"]
    for i, fy in enumerate(("0.70", "0.8", "")):
        save_rgb(ptl / "images" / f"{i}.jpg", np.full((64, 64, 3), 90, np.uint8))
        lines.append(f"images/{i}.jpg,train,p{i},0.5,{fy},0.5,1.0,7,1,0")
    (ptl / "labels.csv").write_text("\n".join(lines) + "\n")
    r = _cli("import-ptl", ptl, "--out", tmp_path / "ds", "--quiet")
    assert r.returncode == 0, r.stderr
    rows = read_manifest(tmp_path / "ds").rows
    assert [flag_value(x.flags, "far_y") for x in rows] == ["0.7000", "0.8000", None]
    assert all(flag_value(x.flags, "aspect") == "4:3" for x in rows)
    r = _cli("negatives", tmp_path / "ds", "--out", tmp_path / "neg", "--quiet")
    assert r.returncode == 0, r.stderr
    neg = read_manifest(tmp_path / "neg").rows
    assert len(neg) == 2 and {x.source for x in neg} == {"ptl:p0", "ptl:p1"}


def test_phone_views_are_what_a_portrait_phone_sees_and_the_view_crop_recovers_the_photo():
    """A phone held in portrait (3:4, 53 deg across) where a 4:3 photo (67 deg) was taken sees a
    window ~0.75 of the photo's width at the same scale, taller than the photo: the rows the
    photo lacks are repeated edges, and the bundle's view crop cuts them off again (to a row)."""
    from crossing_assist.data_tools.augment import phone_views, portrait_sets
    from crossing_assist.geometry import view_rows, window_fov

    rng = np.random.default_rng(0)
    photo = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    views = phone_views(photo, 0.1, x_to_bin(0.1), 3, fov_deg=53.0, train_fov_deg=67.0)
    cw = round(640 * np.tan(np.radians(26.5)) / np.tan(np.radians(33.5)))
    assert cw == 482
    for (frame, x, b, inside), x0 in zip(views, (0, (640 - cw) // 2, 640 - cw)):
        assert frame.shape == (round(cw * 4 / 3), cw, 3)
        top, rows = view_rows(frame.shape[0], cw, 53.0, (168, 224), 67.0)
        assert abs(rows - 480) <= 2                                   # the photo's rows, give or take one
        pad = (frame.shape[0] - 480) // 2
        assert np.array_equal(frame[pad:pad + 480], photo[:, x0:x0 + cw])
        assert inside == (x0 <= 0.1 * 640 < x0 + cw) and b == (x_to_bin(x) if inside else 1)
    with pytest.raises(ValueError, match="wider than the photo"):
        phone_views(photo, 0.5, 6, 1, fov_deg=90.0, train_fov_deg=67.0)
    sets = portrait_sets(photo, 0.5, 6, 2, portrait_fov_deg=53.0, train_fov_deg=67.0)
    assert [len(v) for v in sets.values()] == [2, 2]
    assert sets["portrait"][0][4] == 53.0
    assert sets["portrait_window"][0][4] == pytest.approx(window_fov(360 / 640, 67.0)) and sets["portrait_window"][0][0].shape == (480, 360, 3)
    assert window_fov(360 / 640, 67.0) == pytest.approx(40.9, abs=0.1)


def test_a_portrait_no_crossing_frame_is_each_portrait_view_once_at_that_views_fov():
    """crossing-eval's portrait sets of a no-crossing frame already 3:4 (half of PTL's negatives):
    the frame itself once a set, at the phone's FOV and at a 3:4 window's; cutting it gave the
    same frame n times at a landscape window's 67 deg (the portrait threshold instead of the
    narrow camera's)."""
    from crossing_assist.data_tools.augment import user_views
    from crossing_assist.geometry import letterbox_geometry, window_fov

    geo = letterbox_geometry()
    frame = _photo()[:, :90]                                  # 120 x 90: 3:4
    views = user_views(frame, None, UNKNOWN, 3, geo)
    assert {k: len(v) for k, v in views.items()} == {"landscape": 1, "portrait": 1, "portrait_window": 1}
    (p,), (w,) = views["portrait"], views["portrait_window"]
    assert p[0] is frame and w[0] is frame and p[1:4] == (None, UNKNOWN, False) == w[1:4]
    assert p[4] == geo.camera_fov_deg[1] and w[4] == pytest.approx(window_fov(9 / 16, geo.train_fov_deg))
    landscape = user_views(_photo(), None, UNKNOWN, 3, geo)   # a 4:3 one is cut as photos are
    assert len(landscape["portrait"]) == len(landscape["portrait_window"]) == 3
    assert user_views(frame, 0.5, 6, 3, geo).keys() == {"landscape"}   # a portrait photo with a crossing
