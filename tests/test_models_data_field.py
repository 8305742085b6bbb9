"""Training frames meet the canvas as the bundle's graph fits camera frames: letterbox with the
content window, field-view variants seeded by (seed, field, image), windows cached beside the
features (issue 12/13)."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from crossing_assist.actions import UNKNOWN, bin_center_x, x_to_bin
from crossing_assist.data_tools.images import load_frame, save_rgb
from crossing_assist.data_tools.manifest import Row, read_manifest, write_manifest
from crossing_assist.geometry import PAD_RGB, content_window, letterbox_geometry
from crossing_assist.models.backbones import create_backbone
from crossing_assist.models.cache import cache_key, compute_features
from crossing_assist.models.data import Variant, load_variants, make_variants

CANVAS = (48, 64)


def _dataset(root):
    rows = []
    shapes = {"land": (60, 80), "square": (60, 60), "portrait": (80, 60), "squashed": (60, 60)}
    for i, (name, (h, w)) in enumerate(shapes.items()):
        img = np.random.default_rng(i).integers(0, 50, (h, w, 3), dtype=np.uint8)
        fx = bin_center_x(3 + 2 * i)
        img[:, int(fx * w) - 1:int(fx * w) + 2] = 255
        save_rgb(root / f"{name}.png", img)
        flags = ("aspect=4:3", "far_y=0.6") if name == "squashed" else ("far_y=0.6",)
        rows.append(Row(f"{name}.png", x_to_bin(fx), fx, f"s{i % 2}", "train", {}, flags))
    save_rgb(root / "none.png", np.random.default_rng(9).integers(0, 50, (60, 80, 3), dtype=np.uint8))
    rows.append(Row("none.png", UNKNOWN, None, "s9", "train", {}, ("far_y=0.5",)))
    write_manifest(root, rows)
    return read_manifest(root)


@pytest.fixture()
def ds(tmp_path):
    return _dataset(tmp_path / "d")


def _pad_outside(img, window):
    x0, x1 = round(window[0] * CANVAS[1]), round(window[1] * CANVAS[1])
    outside = np.concatenate([img[:, :x0], img[:, x1:]], axis=1).reshape(-1, 3)
    return outside.size == 0 or bool(np.all(outside == np.asarray(PAD_RGB, np.uint8)))


def test_make_variants_puts_identity_first_then_field_views():
    vs = make_variants(True, (8.0,), 2)
    assert vs[0] == Variant() and [v.tag for v in vs[-2:]] == ["field0", "field1"]
    assert len(vs) == 2 * 3 + 2 and len({v.tag for v in vs}) == len(vs)


def _served(h, w):
    """The content window of an h x w frame as a letterbox bundle's graph gets it (its view crop)."""
    top, rows = letterbox_geometry().rows_seen(h, w, letterbox_geometry().camera_fov(w, h), CANVAS)
    return content_window(rows, w, CANVAS)


def test_letterbox_variants_carry_the_content_window(ds):
    ident = (Variant(), Variant(mirrored=True))
    want = {"land.png": (0.0, 1.0), "square.png": _served(60, 60),
            "portrait.png": _served(80, 60), "squashed.png": (0.0, 1.0)}   # 4:3 once unsquashed
    whole = content_window(80, 60, CANVAS)   # the portrait frame letterboxed whole: narrower than served
    assert want["portrait.png"][1] - want["portrait.png"][0] > whole[1] - whole[0]
    for row in ds.rows[:4]:
        out = load_variants(ds, row, CANVAS, ident, 67.0, fit="letterbox")
        for (img, fx, lab, win), v in zip(out, ident):
            assert img.shape == (*CANVAS, 3) and win == pytest.approx(want[row.image])
            assert _pad_outside(img, win)
            x = 1 - row.far_x if v.mirrored else row.far_x
            assert fx == pytest.approx(x) and lab == x_to_bin(x)
            # the bright bar sits at the goal's place inside the window
            lo, hi = round(win[0] * CANVAS[1]), round(win[1] * CANVAS[1])
            col = lo + int(np.argmax(img[CANVAS[0] // 2, lo:hi, 0].astype(int)))
            assert abs((col + 0.5) / CANVAS[1] - (win[0] + (win[1] - win[0]) * x)) < 2.5 / CANVAS[1]
    stretch = load_variants(ds, ds.rows[2], CANVAS, ident, 67.0, fit="stretch")
    assert all(w == (0.0, 1.0) for *_, w in stretch)


def test_training_frames_are_the_pixels_the_bundle_serves(ds):
    """Each frame, plain, is exactly what the exported bundle's graph gets from Engine.predict: a
    portrait frame through the view crop (it was letterboxed whole, so the model learned portrait
    frames at 3/4 of the scale it was served them)."""
    from crossing_assist.geometry import letterbox

    served = letterbox_geometry()   # what crossing-export writes for a letterbox model (view zoom 1)
    for row in ds.rows[:4]:
        (img, _, _, _), = load_variants(ds, row, CANVAS, (Variant(),), 67.0, fit="letterbox")
        frame = load_frame(ds.image_path(row), row.flags)
        assert np.array_equal(img, letterbox(served.camera_view(frame, CANVAS), CANVAS, PAD_RGB)), row.image


def test_field_views_turn_the_goal_at_its_height_in_the_rows_kept(ds, monkeypatch):
    """far_y is a fraction of the photo's height; a portrait frame loses rows to the view crop, so
    the roll must get the goal's height in the rows kept (and far_y = 0 is a height, not missing)."""
    from crossing_assist.data_tools import augment

    seen = {}
    real = augment.field_view

    def spy(image, far_x, far_y, *args, **kwargs):
        seen[image.shape] = far_y
        return real(image, far_x, far_y, *args, **kwargs)

    monkeypatch.setattr(augment, "field_view", spy)
    portrait = ds.rows[2]                                         # 80 x 60, far_y 0.6
    top, rows = letterbox_geometry().rows_seen(80, 60, letterbox_geometry().camera_fov(60, 80), CANVAS)
    assert rows < 80                                              # the view crop removes rows here
    load_variants(ds, portrait, CANVAS, (Variant(field=0),), 67.0, fit="letterbox")
    assert seen[(rows, 60, 3)] == pytest.approx((0.6 * 80 - top) / rows)
    at_top = replace(ds.rows[0], flags=("far_y=0",))
    seen.clear()
    load_variants(ds, at_top, CANVAS, (Variant(field=0),), 67.0, fit="letterbox")
    assert list(seen.values()) == [0.0]


def test_field_variants_are_seeded_by_seed_field_and_image(ds):
    fields = tuple(Variant(field=i) for i in range(6))
    row = ds.rows[0]
    a = load_variants(ds, row, CANVAS, fields, 67.0, fit="letterbox", seed=1)
    b = load_variants(ds, row, CANVAS, fields, 67.0, fit="letterbox", seed=1)
    c = load_variants(ds, row, CANVAS, fields, 67.0, fit="letterbox", seed=2)
    for (ia, fa, la, wa), (ib, fb, lb, wb) in zip(a, b):
        np.testing.assert_array_equal(ia, ib)
        assert (la, wa) == (lb, wb) and (fa == fb or (np.isnan(fa) and np.isnan(fb)))
    assert any(not np.array_equal(x[0], y[0]) for x, y in zip(a, c))
    assert len({tuple(w) for *_, w in a}) > 1                           # several phone aspects
    for img, fx, lab, win in a:
        assert _pad_outside(img, win) and 1 <= lab <= 12 and lab == x_to_bin(fx)
    unknown = load_variants(ds, ds.rows[4], CANVAS, fields, 67.0, fit="letterbox")
    assert all(lab == UNKNOWN and np.isnan(fx) for _, fx, lab, _ in unknown)


def test_windows_are_cached_with_the_features_and_keyed_by_fit_and_seed(ds, tmp_path):
    torch.manual_seed(0)
    bb = create_backbone("mobilenet_v3_small", weights="none")
    vs = make_variants(False, (), 2)
    k = len(bb.blocks) - 2
    fs = compute_features(bb, k, ds, CANVAS, vs, 67.0, tmp_path / "c", progress=False, fit="letterbox", seed=0)
    assert (fs.path / "window.npy").is_file() and fs.window.shape == (len(ds.rows) * 3, 2)
    for i, row in enumerate(ds.rows):
        want = [w for *_, w in load_variants(ds, row, CANVAS, vs, 67.0, fit="letterbox", seed=0)]
        np.testing.assert_allclose(fs.window[fs.row == i], want, atol=1e-6)
    keys = {cache_key(bb, k, CANVAS, vs, 67.0, ds, fit, seed) for fit in ("letterbox", "stretch") for seed in (0, 1)}
    assert len(keys) == 4
    ident = make_variants(False)
    assert cache_key(bb, k, CANVAS, ident, 67.0, ds) == cache_key(bb, k, CANVAS, ident, 67.0, ds, "stretch", 5)
    # a row's flags change its pixels (aspect=4:3) or its field views' goals (far_y): a new key
    ds2 = replace(ds, rows=[replace(ds.rows[0], flags=("far_y=0.3",)), *ds.rows[1:]])
    assert cache_key(bb, k, CANVAS, vs, 67.0, ds2, "letterbox") != cache_key(bb, k, CANVAS, vs, 67.0, ds, "letterbox")


def test_field_view_features_are_keyed_by_the_field_recipe(ds, monkeypatch):
    """Changing what a field view draws (its aspects) must not reuse features cached under the old recipe;
    features without field views keep their key."""
    from crossing_assist.data_tools import augment

    bb = create_backbone("mobilenet_v3_small", weights="none")
    k = len(bb.blocks) - 2
    fields, ident = make_variants(False, (), 2), make_variants(False)
    before = cache_key(bb, k, CANVAS, fields, 67.0, ds, "letterbox"), cache_key(bb, k, CANVAS, ident, 67.0, ds)
    ablated = make_variants(False, (), 2, ("roll",))   # an ablation leaves a step out: other views
    assert cache_key(bb, k, CANVAS, ablated, 67.0, ds, "letterbox") != before[0]
    zoomed = make_variants(False, (), 2, (), 1.7)      # magnified views: other views
    assert cache_key(bb, k, CANVAS, zoomed, 67.0, ds, "letterbox") != before[0]
    assert cache_key(bb, k, CANVAS, make_variants(False, (), 2, (), 1.0), 67.0, ds, "letterbox") == before[0]
    monkeypatch.setattr(augment, "FIELD_ASPECTS", ((3 / 4, 1.0),))
    assert cache_key(bb, k, CANVAS, fields, 67.0, ds, "letterbox") != before[0]
    assert cache_key(bb, k, CANVAS, ident, 67.0, ds) == before[1]


def test_predict_split_reads_strips_inside_each_samples_window(ds, tmp_path):
    from crossing_assist.models.heads import create_head
    from crossing_assist.models.policy import Policy, policy_config
    from crossing_assist.models.train import Split, predict_split

    torch.manual_seed(0)
    bb = create_backbone("mobilenet_v3_small", weights="none")
    k = len(bb.blocks) - 2
    head = create_head("spatial", bb.num_features, 13)
    with torch.no_grad():
        for prm in head.parameters():
            prm.mul_(8.0)   # spread the logits of a random init
    policy = Policy(bb, head, policy_config(bb, "spatial", 13, input_size=CANVAS, fit="letterbox")).eval()
    fs = compute_features(bb, k, ds, CANVAS, make_variants(False), 67.0, tmp_path / "c", progress=False,
                          fit="letterbox")
    feats = torch.from_numpy(np.array(fs.feats))
    full = Split(feats, fs.labels, fs.far_x, torch.tensor([[0.0, 1.0]] * len(fs.labels)))
    real = Split(feats, fs.labels, fs.far_x, torch.from_numpy(fs.window))
    a, b = predict_split(policy, full, k), predict_split(policy, real, k)
    narrow = np.flatnonzero(fs.window[:, 1] - fs.window[:, 0] < 0.99)      # square and portrait photos
    wide = np.flatnonzero(fs.window[:, 1] - fs.window[:, 0] >= 0.99)
    assert len(narrow) and len(wide)
    np.testing.assert_allclose(a[wide], b[wide], atol=1e-6)
    assert np.abs(a[narrow] - b[narrow]).max() > 1e-4


@pytest.mark.parametrize("argv, message", [
    (["--field", "2", "--field-without", "roll,sky"], "Invalid field_without roll,sky; valid: mirror, roll, aspect, corruption, night"),
    (["--field-without", "roll"], "Invalid field_without needs --field >= 1"),
    (["--field", "2", "--field-zoom", "0.5"], "Invalid field_zoom 0.5; valid: 1..4"),
    (["--field-zoom", "1.5"], "Invalid field_zoom needs --field >= 1"),
])
def test_crossing_train_refuses_a_bad_field_without_or_zoom_in_one_line(tmp_path, capsys, argv, message):
    from crossing_assist.models.cli import train_main

    assert train_main(["--data", str(tmp_path), "--out", str(tmp_path / "run"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {message}") and "\n" not in err
    assert not (tmp_path / "run").exists()
