"""Camera geometry (issue 12): orientation, FOV range, frame shapes, and the bundle's schema-2
``geometry`` block: parsing, one-line errors, schema 1 read as stretch, Bundle.camera_fov, and
an edited bundle.json caught against the graph."""

import json

import numpy as np
import pytest
from runtime_toy import LANDSCAPE_FOV, PORTRAIT_FOV, TOY2, make_toy_bundle, toy_meta

from crossing_assist.bundle import BundleError, parse_meta, read_bundle
from crossing_assist.geometry import (
    Geometry,
    GeometryError,
    check_fov,
    check_frame_shape,
    content_window,
    letterbox,
    letterbox_box,
    level,
    level_angle,
    orientation,
    parse_size,
    window_x,
)


def test_parse_size_returns_height_width_whichever_order_the_user_types():
    """One parser, one returned order (H, W): crossing-train types a canvas HxW, crossing-data a
    frame WxH; one number is a square; anything else is one argparse error line."""
    import argparse

    assert parse_size("168x224", "HxW") == (168, 224) and parse_size("320x240", "WxH") == (240, 320)
    assert parse_size("64") == (64, 64) and parse_size("64", "WxH") == (64, 64)
    for bad in ("", "x", "1x2x3", "axb", "0x5", "-3x4"):
        with pytest.raises(argparse.ArgumentTypeError, match="expected WxH in pixels"):
            parse_size(bad, "WxH")


def test_orientation_and_fov_per_orientation():
    assert orientation(640, 480) == "landscape" and orientation(480, 640) == "portrait"
    assert orientation(500, 500) == "landscape"
    g = Geometry(camera_fov_deg=(67.0, 53.0))
    assert g.camera_fov(640, 480) == 67.0 and g.camera_fov(480, 640) == 53.0
    assert g.camera_fov(480, 640, override=70.0) == 70.0
    for bad in (10, 19.9, 170.5, 200, "wide", None, float("nan")):
        with pytest.raises(GeometryError) as e:
            check_fov(bad) if bad is not None else g.camera_fov(480, 640, override=bad or "x")
        assert "\n" not in str(e.value) and "20..170" in str(e.value)
    assert check_fov(20) == 20.0 and check_fov(170) == 170.0


def test_frame_shapes_refused():
    check_frame_shape(480, 640)
    check_frame_shape(8, 64)                       # 8:1 is the limit
    for h, w in [(1, 100), (100, 1), (7, 40), (10, 100), (100, 10), (30, 241)]:
        with pytest.raises(GeometryError) as e:
            check_frame_shape(h, w)
        assert "\n" not in str(e.value) and "Invalid frame" in str(e.value)


def test_numpy_letterbox_matches_the_box_and_pads_with_pad_rgb():
    rng = np.random.default_rng(0)
    for h, w in [(120, 160), (160, 120), (90, 160), (160, 90), (50, 50), (16, 112)]:
        img = rng.integers(0, 50, (h, w, 3), dtype=np.uint8)
        out = letterbox(img, (48, 64), (124, 116, 104))
        top, left, nh, nw = letterbox_box(h, w, (48, 64))
        pad = np.all(out == np.array([124, 116, 104], np.uint8), axis=-1)
        box = np.zeros((48, 64), bool)
        box[top:top + nh, left:left + nw] = True
        np.testing.assert_array_equal(~pad, box)
        x0, x1 = content_window(h, w, (48, 64))
        assert (x0, x1) == (left / 64, (left + nw) / 64)


def test_window_x_moves_the_goal_and_clips_into_edge_strips():
    assert window_x(0.5, 0.25, 0.5) == pytest.approx(0.5)
    assert window_x(0.3, 0.25, 0.5) == pytest.approx(0.1)
    assert 0 < window_x(0.1, 0.25, 0.5) < 1 / 12          # out of view to the left: strip 1
    assert 11 / 12 < window_x(0.9, 0.25, 0.5) < 1         # to the right: strip 12


# ----------------------------------------------------------------------------- bundle schema 2

def _err(meta) -> str:
    with pytest.raises(BundleError) as e:
        parse_meta(meta, need_bytes=False)
    msg = str(e.value)
    assert "\n" not in msg
    return msg


def test_schema2_geometry_parses():
    b = parse_meta(toy_meta(TOY2), need_bytes=False)
    assert b.schema_version == 3 and b.geometry.fit == "stretch" and not b.geometry.view_crop
    assert b.geometry.camera_fov_deg == (LANDSCAPE_FOV, PORTRAIT_FOV) and b.geometry.train_fov_deg == 67.0
    lb = toy_meta(TOY2)
    lb["geometry"].update(fit="letterbox", pad_rgb=[1, 2, 3])
    assert parse_meta(lb, need_bytes=False).geometry.pad_rgb == (1, 2, 3)
    assert not parse_meta(lb, need_bytes=False).geometry.view_crop          # absent: no crop
    lb["geometry"]["view_crop"] = True
    assert parse_meta(lb, need_bytes=False).geometry.view_crop
    assert not parse_meta(lb | {"schema_version": 2}, need_bytes=False).geometry.view_crop   # schema 2: never


@pytest.mark.parametrize("edit, words", [
    (lambda g: g.update(fit="crop"), "geometry.fit"),
    (lambda g: g.pop("fit"), "fit"),
    (lambda g: g.update(fit="letterbox"), "pad_rgb"),                         # letterbox needs pad_rgb
    (lambda g: g.update(fit="letterbox", pad_rgb=[1, 2]), "pad_rgb"),
    (lambda g: g.update(fit="letterbox", pad_rgb=[1, 2, 256]), "pad_rgb"),
    (lambda g: g.update(fit="letterbox", pad_rgb=[1.5, 2, 3]), "pad_rgb"),
    (lambda g: g.update(fit="letterbox", pad_rgb="grey"), "pad_rgb"),
    (lambda g: g["camera_fov_deg"].update(portrait=10.0), "camera_fov_deg.portrait"),
    (lambda g: g["camera_fov_deg"].update(landscape=175.0), "camera_fov_deg.landscape"),
    (lambda g: g["camera_fov_deg"].pop("portrait"), "portrait"),
    (lambda g: g.update(camera_fov_deg=67.0), "camera_fov_deg"),
    (lambda g: g.update(strips="canvas"), "strips"),
    (lambda g: g.update(fit="letterbox", pad_rgb=[1, 2, 3], view_crop="yes"), "view_crop"),
])
def test_schema2_geometry_errors_are_one_line(edit, words):
    meta = toy_meta(TOY2)
    edit(meta["geometry"])
    assert words in _err(meta)


def test_schema2_without_geometry_is_refused_and_schema5_unsupported():
    meta = toy_meta(TOY2)
    del meta["geometry"]
    assert "geometry" in _err(meta)
    assert "geometry" in _err(meta | {"schema_version": 2})
    assert "unsupported" in _err(toy_meta(TOY2) | {"schema_version": 5})


def test_schema1_reads_as_stretch_with_one_fov(tmp_path):
    b = read_bundle(make_toy_bundle(tmp_path / "b1"))
    assert b.schema_version == 1 and b.geometry.fit == "stretch"
    assert b.geometry.camera_fov_deg == (90.0, 90.0)
    assert b.camera_fov(640, 480) == 90.0 == b.camera_fov(480, 640)


def test_bundle_camera_fov_by_orientation_and_override(tmp_path):
    b = read_bundle(make_toy_bundle(tmp_path / "b2", TOY2))
    assert b.camera_fov(640, 480) == LANDSCAPE_FOV
    assert b.camera_fov(480, 640) == PORTRAIT_FOV
    assert b.camera_fov(480, 640, override=60.0) == 60.0 == b.camera_fov(640, 480, override=60)
    with pytest.raises(GeometryError):
        b.camera_fov(480, 640, override=10.0)


@pytest.mark.parametrize("edit, key", [
    (lambda m: m.update(fov_deg=70.0), "fov_deg"),
    (lambda m: m["geometry"]["camera_fov_deg"].update(portrait=60.0), "geometry"),
    (lambda m: m["geometry"].update(fit="letterbox", pad_rgb=[0, 0, 0]), "geometry"),
    (lambda m: m["geometry"].update(sensor_aspect=16 / 9), "geometry"),
])
def test_edited_geometry_in_bundle_json_is_caught_against_the_graph(tmp_path, edit, key):
    from crossing_assist.runtime.engine import Engine

    folder = make_toy_bundle(tmp_path / "b", TOY2)
    Engine(folder)                                   # as written: fine
    meta = json.loads((folder / "bundle.json").read_text())
    edit(meta)
    (folder / "bundle.json").write_text(json.dumps(meta))
    read_bundle(folder)                              # still a valid bundle.json on its own
    with pytest.raises(BundleError) as e:
        Engine(folder)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"bundle.json: {key}") and "re-export" in msg


# ----------------------------------------------------------------------------- the view crop (schema 3)


def test_view_rows_keeps_the_training_cameras_angular_scale():
    """Rows beyond what the 4:3 canvas shows at the training photos' pixels per degree (or, for a
    camera wider than the training one, at the scale that fits its width) go; columns never do.
    Canvas 168 x 224, training camera 67 deg across."""
    from crossing_assist.geometry import view_rows

    canvas = (168, 224)
    assert view_rows(480, 640, 67.0, canvas) == (0, 480)             # the training camera: nothing
    assert view_rows(720, 1280, 67.0, canvas) == (0, 720)            # 16:9 video: already shorter
    assert view_rows(640, 480, 40.8, canvas) == (0, 640)             # a 3:4 window of a 67 deg 4:3 photo
    assert view_rows(640, 480, 40.0, canvas) == (-8, 655)            # narrower still: a little shorter, padded
    assert view_rows(480, 640, 41.0, canvas) == (-185, 850)          # a landscape camera zoomed in: padded
    top, rows = view_rows(640, 480, 53.0, canvas)                    # a phone held in portrait
    assert rows == 478 and top == 81                                 # its middle ~3:3
    assert view_rows(480, 640, 100.0, canvas) == (0, 480)            # a wide-angle lens, 4:3: fitted by width
    assert view_rows(640, 480, 100.0, canvas) == (140, 360)          # ... held in portrait: a 4:3 band
    assert view_rows(64, 1, 67.0, canvas) == (31, 1)                 # never below one row


def test_a_zoomed_landscape_frame_is_padded_to_the_training_scale_not_magnified():
    """A 4:3 frame from a camera narrower than the training one (zoomed in, ~41 deg) is shorter than
    the view the canvas shows at the training scale: its rows are padded with pad_rgb above and
    below (take_rows), so the letterbox shows it at that scale (its width on 41/67 of the canvas,
    in tangents) instead of filling the canvas magnified ~1.8 times."""
    from crossing_assist.geometry import content_window, take_rows

    frame = np.full((48, 64, 3), 200, np.uint8)
    geo = Geometry(view_crop=True, pad_rgb=(1, 2, 3))
    seen = geo.view(frame, 41.0, (168, 224))
    top, rows = geo.rows_seen(48, 64, 41.0, (168, 224))
    assert seen.shape == (rows, 64, 3) and rows > 48 and top < 0
    assert np.array_equal(seen[-top:-top + 48], frame)
    assert (seen[0] == (1, 2, 3)).all() and (seen[-1] == (1, 2, 3)).all()
    x0, x1 = content_window(seen.shape[0], seen.shape[1], (168, 224))   # the frame's columns on the canvas
    ratio = np.tan(np.radians(20.5)) / np.tan(np.radians(33.5))
    assert abs((x1 - x0) - ratio) < 0.01, (x0, x1, ratio)
    assert take_rows(frame, 8, 30).base is frame                        # inside: a view, no copy
    assert geo.rows_seen(48, 64, 67.0, (168, 224)) == (0, 48)          # the training camera: as it is


def test_geometry_view_crops_only_when_the_bundle_says_so():
    frame = np.arange(640 * 480 * 3, dtype=np.uint32).reshape(640, 480, 3)
    on = Geometry(view_crop=True).view(frame, 53.0, (168, 224))
    assert on.shape == (478, 480, 3) and np.array_equal(on, frame[81:559])
    assert Geometry().view(frame, 53.0, (168, 224)) is frame
    assert Geometry(view_crop=True).rows_seen(640, 480, 53.0, (168, 224)) == (81, 478)
    assert Geometry().rows_seen(640, 480, 53.0, (168, 224)) == (0, 640)


def test_view_zoom_magnifies_a_narrower_cameras_frame_up_to_it():
    """Schema 4, ``view_zoom``: a portrait phone (53 deg, t = 1.33 at a 67-deg training camera) keeps
    fewer rows, shown magnified min(t, zoom) times; a large zoom fills the canvas with a 4:3 band;
    the training camera and wider ones are not touched; columns never go."""
    import math

    from crossing_assist.geometry import view_rows

    canvas = (168, 224)
    t = math.tan(math.radians(33.5)) / math.tan(math.radians(26.5))
    for zoom in (1.0, 1.2, 1.3, 2.0, 4.0):
        rows = math.floor(480 * 0.75 * max(1.0, t / zoom) + 0.5)
        assert view_rows(640, 480, 53.0, canvas, zoom=zoom) == ((640 - rows) // 2, rows)
        assert view_rows(480, 640, 67.0, canvas, zoom=zoom) == (0, 480)       # the training camera
        assert view_rows(640, 480, 100.0, canvas, zoom=zoom) == (140, 360)    # a wider one: as before
    assert view_rows(640, 480, 53.0, canvas, zoom=2.0) == (140, 360)          # filled: 4:3 rows
    assert Geometry(view_crop=True, view_zoom=2.0).rows_seen(640, 480, 53.0, canvas) == (140, 360)
    with pytest.raises(GeometryError, match="view zoom"):
        Geometry(view_crop=True, view_zoom=0.5)
    with pytest.raises(GeometryError, match="needs the view crop"):
        Geometry(view_zoom=1.3)


def test_schema4_carries_view_zoom_and_only_a_zoom_makes_a_bundle_schema4():
    """The writer keeps schema 3 (readable by older apps) unless the bundle has a view zoom;
    a reader takes view_zoom from schema 4 only, with the view crop, in 1..4."""
    from crossing_assist.bundle import schema_for

    plain = Geometry(fit="letterbox", view_crop=True)
    zoomed = Geometry(fit="letterbox", view_crop=True, view_zoom=1.3)
    assert schema_for(None) == 1 and schema_for(plain) == 3 and schema_for(zoomed) == 4
    assert "view_zoom" not in plain.to_json() and zoomed.to_json()["view_zoom"] == 1.3
    meta = toy_meta(TOY2) | {"schema_version": 4}
    meta["geometry"].update(fit="letterbox", pad_rgb=[1, 2, 3], view_crop=True, view_zoom=1.3)
    assert parse_meta(meta, need_bytes=False).geometry.view_zoom == 1.3
    assert parse_meta(meta | {"schema_version": 3}, need_bytes=False).geometry.view_zoom == 1.0   # schema 3: never
    for bad, words in ((0.9, "geometry.view_zoom"), (5.0, "geometry.view_zoom"), ("2", "geometry.view_zoom")):
        meta["geometry"]["view_zoom"] = bad
        assert words in _err(meta)
    meta["geometry"].update(view_zoom=1.3, view_crop=False)
    assert "needs geometry.view_crop" in _err(meta)


@pytest.mark.parametrize("crop", [True, False])
def test_engine_crops_a_portrait_frame_to_the_training_view(tmp_path, crop):
    """The toy reads the brightest strip, averaged over rows: a bright bar above the portrait
    view (strip 3) beats a dimmer one inside it (strip 9) only when the frame is not cropped."""
    from crossing_assist.runtime.engine import Engine
    from crossing_assist.testing.toy_bundle import Toy

    toy = Toy(samples=1, drop_p=0.0, geometry=Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0),
                                                       train_fov_deg=67.0, view_crop=crop))
    folder = make_toy_bundle(tmp_path / "b", toy)
    assert read_bundle(folder).geometry.view_crop is crop
    frame = np.zeros((120, 60, 3), np.uint8)                          # portrait: keeps rows 40..79
    frame[:40, 10:15] = 255                                           # strip 3, above the view
    frame[40:80, 45:50] = 200                                         # strip 10, in view
    pred = Engine(folder).predict(frame)
    assert pred.ok and pred.orientation == "portrait" and pred.fov_deg == 53.0
    assert pred.action == (10 if crop else 3)


# ----------------------------------------------------------------------------- sensor_aspect: a crop's FOV


SENSOR = Geometry(camera_fov_deg=(67.0, 53.0), sensor_aspect=4 / 3)


def test_a_frame_narrower_than_the_sensor_gets_its_crops_fov():
    """With sensor_aspect 4:3, 9:16 portrait video is a crop of the 3:4 portrait sensor:
    2 atan(0.75 tan(26.5 deg)) ~ 41.0 deg across, not 53; without the field, 53 as before."""
    assert SENSOR.camera_fov(1080, 1920) == pytest.approx(41.005, abs=0.001)
    assert Geometry(camera_fov_deg=(67.0, 53.0)).camera_fov(1080, 1920) == 53.0
    assert SENSOR.camera_fov(1000, 1000) == pytest.approx(52.801, abs=0.001)     # 1:1: a crop of 4:3 landscape
    assert SENSOR.camera_fov(480, 640) == 53.0 and SENSOR.camera_fov(640, 480) == 67.0     # the full sensor
    assert SENSOR.camera_fov(1920, 1080) == 67.0 and SENSOR.camera_fov(600, 640) == 53.0   # rows cropped only
    for w, h in ((1080, 1920), (480, 640), (1000, 1000)):
        assert SENSOR.camera_fov(w, h, override=60.0) == 60.0            # an override is used as given
    with pytest.raises(GeometryError, match="20..170"):
        SENSOR.camera_fov(100, 800)                                       # 1:8: ~9.5 deg, refused like any FOV


def test_the_view_crop_of_9_16_video_keeps_a_3_4_view_with_sensor_aspect():
    """The training canvas (4:3, 67 deg across) shows ~53 deg vertically; a 9:16 frame spans the
    sensor's long side (~67 deg) vertically, so the crop keeps ~3/4 of its rows (a 3:4 view).
    With the 53 deg default the model saw a square (zoomed in)."""
    crop = Geometry(camera_fov_deg=(67.0, 53.0), view_crop=True, sensor_aspect=4 / 3)
    top, rows = crop.rows_seen(1920, 1080, crop.camera_fov(1080, 1920), (168, 224))
    assert 1080 / rows == pytest.approx(3 / 4, abs=0.01) and top == (1920 - rows) // 2
    old = Geometry(camera_fov_deg=(67.0, 53.0), view_crop=True)
    assert old.rows_seen(1920, 1080, old.camera_fov(1080, 1920), (168, 224))[1] == pytest.approx(1080, abs=10)


def test_sensor_aspect_is_read_validated_and_round_tripped(tmp_path):
    from crossing_assist.testing.toy_bundle import Toy

    meta = toy_meta(TOY2)                                                           # 80 / 50 deg
    assert parse_meta(meta, need_bytes=False).geometry.sensor_aspect is None        # absent: old rule
    for version in (2, 3):
        meta = toy_meta(TOY2) | {"schema_version": version}
        meta["geometry"]["sensor_aspect"] = 4 / 3
        b = parse_meta(meta, need_bytes=False)
        assert b.geometry.sensor_aspect == 4 / 3 and b.camera_fov(1080, 1920) == pytest.approx(38.553, abs=0.001)
        assert b.geometry.to_json() == meta["geometry"]
    for bad in (0.9, 3.5, "4:3", True, float("inf")):
        meta["geometry"]["sensor_aspect"] = bad
        assert "geometry.sensor_aspect" in _err(meta)
    geo = Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), view_crop=True, sensor_aspect=4 / 3)
    folder = make_toy_bundle(tmp_path / "b", Toy(samples=1, drop_p=0.0, geometry=geo))
    b = read_bundle(folder)
    assert b.geometry == geo and b.raw["geometry"]["sensor_aspect"] == 4 / 3


def test_parse_ratio_reads_w_to_h_and_refuses_the_rest():
    """One W:H reader for --aspect, the aspect=W:H flag and stamp_bundle --sensor-aspect."""
    from crossing_assist.data_tools.images import ImageError, true_aspect
    from crossing_assist.geometry import parse_ratio

    assert parse_ratio("4:3") == 4 / 3 and parse_ratio("3:4") == 0.75 and parse_ratio(" 16 : 9 ") == 16 / 9
    for bad in ("4", "4:0", "0:3", "-4:3", "a:b", "4:3:2", "inf:1", ""):
        with pytest.raises(ValueError):
            parse_ratio(bad)
    img = np.zeros((30, 30, 3), np.uint8)
    assert true_aspect(img, ("aspect=4:3",)).shape == (30, 40, 3)
    with pytest.raises(ImageError, match="expected W:H"):
        true_aspect(img, ("aspect=4:0",))


@pytest.mark.parametrize("bad", ["3x4", "3:0", "-3:4"])
def test_photo_clip_refuses_a_bad_aspect_in_one_line(tmp_path, capsys, bad):
    from crossing_assist.data_tools.cli import main

    assert main(["photo-clip", str(tmp_path), "--out", str(tmp_path / "c.mp4"), f"--aspect={bad}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "expected W:H" in err[0] and not (tmp_path / "c.mp4").exists()


# ----------------------------------------------------------------------------- levelling a rolled camera


def test_level_undoes_a_roll_inside_the_cameras_view_and_pads_the_rest():
    """A phone turned by r rolls the scene by r in its frame (augment.roll); levelling by the
    sensor's r gives the level frame back wherever the rolled camera saw it, pad_rgb elsewhere;
    levelling the wrong way does not."""
    from crossing_assist.data_tools.augment import roll

    yy, xx = np.mgrid[0:90, 0:120]
    img = np.stack([xx * 2, yy * 2, (xx + yy)], axis=-1).clip(0, 255).astype(np.uint8)   # smooth ramps
    img[40:44] = 250                                                                        # a horizon line
    rolled, _, _ = roll(img, 0.5, 0.5, 6, 12.0)
    back = level(rolled, 12.0, (1, 2, 3))
    inner = np.zeros(img.shape[:2], bool)
    inner[25:65, 30:90] = True                   # well inside what the rolled camera saw
    err = np.abs(back.astype(int) - img.astype(int)).max(axis=-1)
    assert np.median(err[inner]) <= 2 and np.abs(level(rolled, -12.0).astype(int) - img.astype(int))[inner].mean() > 20
    assert (back[0, 0] == (1, 2, 3)).all() and (back[-1, -1] == (1, 2, 3)).all()   # corners the camera missed
    rows = back[:, 30:90].mean(axis=(1, 2))
    assert 39 <= int(np.argmax(rows)) <= 44                                          # the horizon is level again


def test_level_angle_clamps_and_leaves_small_or_missing_rolls_alone():
    assert level_angle(12.0) == 12.0 and level_angle(-30.5) == -30.5
    assert level_angle(60.0) == 45.0 and level_angle(-90.0) == -45.0
    assert level_angle(0.3) == 0.0 and level_angle(None) == 0.0 and level_angle(float("nan")) == 0.0
    img = np.zeros((10, 12, 3), np.uint8)
    assert level(img, 0.2) is img and level(img, float("nan")) is img


def test_engine_levels_a_frame_by_the_sensors_roll(tmp_path):
    """The toy reads the brightest strip. A blob above the middle of a level frame lies in strip
    6 or 7; the camera turned 30 deg clockwise carries it to the left; given the sensor's roll the
    engine sees it in the middle again, and Pipeline.step passes the roll on."""
    from crossing_assist.data_tools.augment import roll
    from crossing_assist.runtime.engine import Engine
    from crossing_assist.runtime.pipeline import Pipeline
    from crossing_assist.testing.toy_bundle import Toy

    folder = make_toy_bundle(tmp_path / "b", Toy(samples=1, drop_p=0.0))
    frame = np.empty((72, 96, 3), np.uint8)
    frame[:] = read_bundle(folder).geometry.pad_rgb   # so the levelled corners read as background
    frame[4:22, 44:52] = 255                          # centred, above the middle
    rolled, _, _ = roll(frame, 0.5, 0.2, 6, 30.0)
    engine = Engine(folder)
    assert engine.predict(frame).action in (6, 7)
    assert engine.predict(rolled).action <= 5
    assert engine.predict(rolled, roll_deg=30.0).action in (6, 7)
    assert engine.predict(rolled, roll_deg=-30.0).action <= engine.predict(rolled).action   # the wrong way: further off
    step = Pipeline(engine).step(rolled, 0.0, roll_deg=30.0)
    assert step.prediction.action in (6, 7)
    # rolled beyond what levelling can bring back (45 deg turned back, 15 trained): no guidance
    for r in (60.5, -75.0, 90.0):
        p = engine.predict(rolled, roll_deg=r)
        assert not p.ok and "hold the phone level" in p.error
    assert engine.predict(rolled, roll_deg=60.0).ok
    assert Pipeline(engine).step(rolled, 0.0, roll_deg=80.0).decision.stop


def test_rolled_too_far_is_beyond_the_levelled_and_trained_roll():
    from crossing_assist.geometry import MAX_GUIDED_ROLL_DEG, MAX_LEVEL_DEG, rolled_too_far

    assert MAX_GUIDED_ROLL_DEG == MAX_LEVEL_DEG + 15
    assert [rolled_too_far(r) for r in (None, float("nan"), 0.0, 45.0, 60.0, 60.01, -61.0, 180.0)] == \
        [False, False, False, False, False, True, True, True]


def test_photo_clip_reads_each_photos_fov_from_its_shape_or_photo_fov(tmp_path, capsys):
    """photo-clip's window FOV (what crossing-demo --fov should get): from a phone's FOV for each
    photo's orientation and aspect (a 3:4 portrait photo is 53 deg across, not the landscape 67),
    from the row's own fov flag (a 2x camera's, read from its EXIF at import), or from --photo-fov,
    which wins; a FOV outside 20..170 is one line."""
    import json

    from crossing_assist.actions import bin_center_x
    from crossing_assist.data_tools.cli import main
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest
    from crossing_assist.geometry import window_fov

    for name, (h, w), flags in (("land", (120, 160), ()), ("port", (160, 120), ()), ("tele", (120, 160), ("fov=36.9",))):
        save_rgb(tmp_path / name / "images" / "a.png", np.full((h, w, 3), 90, np.uint8))
        write_manifest(tmp_path / name, [Row("images/a.png", 7, bin_center_x(7), "s", "val", {}, flags)])
    runs = {"land": ("3:4", None, 67.0), "port": ("9:16", None, 53.0), "port60": ("9:16", 60.0, 60.0),
            "tele": ("3:4", None, 36.9), "tele50": ("3:4", 50.0, 50.0)}
    for tag, (aspect, photo_fov, want) in runs.items():
        out = tmp_path / f"{tag}.mp4"
        args = ["photo-clip", str(tmp_path / tag[:4]), "--out", str(out), "--aspect", aspect, "--count", "1",
                "--seconds-each", "0.5", "--height", "64"] + ([] if photo_fov is None else ["--photo-fov", str(photo_fov)])
        assert main(args) == 0
        side = json.loads(out.with_suffix(".json").read_text())
        w = round(float(aspect.split(":")[0]) / float(aspect.split(":")[1]) * 64)
        pw = round(64 * (120 / 160 if tag.startswith("port") else 160 / 120))
        assert side["photo_fov_deg"] == [want]
        assert side["fov_deg"] == pytest.approx(window_fov(w / pw, want), abs=1e-3), tag
        assert f"--fov {side['fov_deg']:.1f}" in capsys.readouterr().out
    assert main(["photo-clip", str(tmp_path / "port"), "--out", str(tmp_path / "x.mp4"), "--photo-fov", "10"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "field of view" in err[0]
