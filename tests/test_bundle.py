"""The bundle reader/writer: validation with one-line errors, atomic writes, graph/json checks."""

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from crossing_assist.actions import get_space
from crossing_assist.bundle import (
    BundleError,
    McSpec,
    check_session,
    embedded_meta,
    read_bundle,
    write_bundle,
)

FAKE_ONNX = b"\x08\x08" + bytes(range(200))  # starts like an ONNX ModelProto (ir_version tag)


def make_meta(n: int = 13, **over) -> dict:
    space = get_space(n)
    meta = {
        "schema_version": 1,
        "model_file": "model.onnx",
        "actions": {"n": n, "names": list(space.names), "bins": [list(g) for g in space.groups]},
        "fov_deg": 90.0,
        "input": {"layout": "NHWC", "dtype": "uint8", "color": "RGB", "size": [224, 224],
                  "mean": [0.485, 0.456, 0.406], "std": [0.229, 0.224, 0.225]},
        "mc": {"samples": 16, "p": 0.5},
        "calibration": {"temperature": 1.3,
                        "conformal": {"coverage": 0.9, "threshold": 0.05, "n_frames": 432},
                        "uncertainty": {"measure": "entropy", "threshold": 1.2}},
        "precision": "fp32",
        "training": {"backbone": "mobilenet_v3_small", "head": "conv", "data": "ptl", "counts": {}},
        "metrics": {"val": {"accuracy": 0.5, "bin_mae": 1.0}},
        "package_version": "0.1.0",
        "provenance": {"command": "test", "created": "2026-01-01T00:00:00Z"},
    }
    meta.update(over)
    return meta


@pytest.fixture
def bundle_dir(tmp_path) -> Path:
    return write_bundle(tmp_path / "b", FAKE_ONNX, make_meta())


def test_roundtrip(bundle_dir):
    b = read_bundle(bundle_dir)
    assert b.actions.n == 13 and b.actions.bins[0] == () and b.actions.bins[7] == (7,)
    assert b.input.size == (224, 224) and b.input.std[2] == pytest.approx(0.225)
    assert b.mc.samples == 16 and b.mc.p == 0.5
    assert b.calibration.temperature == 1.3
    assert b.calibration.conformal.threshold == 0.05
    assert b.calibration.uncertainty.measure == "entropy"
    assert b.model_path == bundle_dir / "model.onnx" and b.model_path.read_bytes() == FAKE_ONNX
    assert b.model_size == len(FAKE_ONNX)
    assert b.space is get_space(13)
    with pytest.raises(Exception):
        b.fov_deg = 60.0  # frozen


def _typed_parts(**over) -> dict:
    """The typed parts of :func:`make_meta`'s literal dict above."""
    from crossing_assist.bundle import Calibration, ConformalSpec, InputSpec, McSpec, UncertaintySpec

    parts = dict(n_actions=13, input=InputSpec((224, 224), (0.485, 0.456, 0.406), (0.229, 0.224, 0.225)),
                 mc=McSpec(16, 0.5), geometry=None,
                 calibration=Calibration(1.3, ConformalSpec(0.9, 0.05, 432), UncertaintySpec("entropy", 1.2)),
                 training=make_meta()["training"], metrics=make_meta()["metrics"],
                 provenance=make_meta()["provenance"])
    parts.update(over)
    return parts


def test_the_writer_lays_out_the_documented_schema():
    """bundle.make_meta (the one writer of bundle metadata) gives exactly the hand-written
    schema-1 dict from the typed parts, and the reader gives the typed parts back."""
    from crossing_assist import bundle as B

    parts = _typed_parts()
    meta = B.make_meta(**parts)
    assert meta == make_meta()
    b = B.parse_meta(meta, need_bytes=False)
    assert (b.input, b.mc, b.calibration, b.actions) == (parts["input"], parts["mc"], parts["calibration"],
                                                       B.ActionsSpec.of(13))


def test_the_writer_writes_schema2_with_geometry_and_portrait_threshold():
    from crossing_assist import bundle as B
    from crossing_assist.geometry import Geometry

    geo = Geometry(fit="letterbox", pad_rgb=(1, 2, 3), camera_fov_deg=(70.0, 50.0), train_fov_deg=66.0)
    cal = B.Calibration(1.0, B.ConformalSpec(0.9, 0.1, 5), B.UncertaintySpec("mutual_info", 0.3, 0.5))
    inp = B.InputSpec((168, 224), (0.5, 0.5, 0.5), (0.5, 0.5, 0.5), resize="bilinear, antialiased")
    meta = B.make_meta(**_typed_parts(geometry=geo, calibration=cal, input=inp, precision="int8"))
    assert meta["schema_version"] == 3 == B.schema_for(geo) and meta["fov_deg"] == 70.0
    b = B.parse_meta(meta, need_bytes=False)
    assert (b.geometry, b.calibration, b.input, b.precision) == (geo, cal, inp, "int8")
    assert b.calibration.uncertainty.threshold_for("portrait") == 0.5
    assert json.loads(B.graph_metadata(meta)["bundle_json"]) == meta


def test_a_narrow_cameras_threshold_round_trips_and_applies_to_narrow_portrait_frames_only():
    """``narrow_threshold`` with ``narrow_fov_deg``: portrait frames at most that wide (9:16 video,
    ~41 deg) take it, wider portrait frames the portrait threshold, landscape frames of any FOV
    theirs; one without the other, or a FOV outside 20..170, is refused in one line."""
    from crossing_assist import bundle as B

    unc = B.UncertaintySpec("far_mass", 0.007, 0.015, narrow_threshold=0.038, narrow_fov_deg=45.0)
    meta = B.make_meta(**_typed_parts(calibration=B.Calibration(1.0, B.ConformalSpec(0.9, 0.1, 5), unc)))
    assert meta["calibration"]["uncertainty"] == {"measure": "far_mass", "threshold": 0.007, "portrait_threshold": 0.015,
                                                  "narrow_threshold": 0.038, "narrow_fov_deg": 45.0}
    got = B.parse_meta(meta, need_bytes=False).calibration.uncertainty
    assert got == unc
    assert [got.threshold_for("portrait", f) for f in (41.0, 45.0, 45.01, 53.0, None)] == [0.038, 0.038, 0.015, 0.015, 0.015]
    assert got.threshold_for("landscape", 41.0) == 0.007
    for change, msg in (({"narrow_fov_deg": None}, "narrow_threshold and narrow_fov_deg go together"),
                        ({"narrow_fov_deg": 10}, "narrow_fov_deg = 10 is out of range"),
                        ({"narrow_threshold": 0}, "narrow_threshold = 0")):
        bad = json.loads(json.dumps(meta))
        bad["calibration"]["uncertainty"].update(change)
        with pytest.raises(B.BundleError, match=msg):
            B.parse_meta(bad, need_bytes=False)


def test_wide_fov_picks_the_threshold_by_the_cameras_width_whatever_the_orientation():
    """``wide_fov_deg``: a frame at least that wide takes ``threshold``, a narrower one
    ``portrait_threshold`` and one at most ``narrow_fov_deg`` ``narrow_threshold``, landscape or
    portrait (a square frame of a 4:3 sensor, ~53 deg, is the portrait phone's); a frame whose FOV
    is not given keeps its orientation's; without the field, orientation decides as before. Not
    above ``narrow_fov_deg``, or outside 20..170: refused in one line."""
    from crossing_assist import bundle as B

    unc = B.UncertaintySpec("far_mass", 0.009, 0.022, narrow_threshold=0.037, narrow_fov_deg=42.0, wide_fov_deg=60.0)
    meta = B.make_meta(**_typed_parts(calibration=B.Calibration(1.0, B.ConformalSpec(0.9, 0.1, 5), unc)))
    assert meta["calibration"]["uncertainty"]["wide_fov_deg"] == 60.0
    got = B.parse_meta(meta, need_bytes=False).calibration.uncertainty
    assert got == unc
    for orientation in ("landscape", "portrait"):
        assert [got.threshold_for(orientation, f) for f in (36.6, 42.0, 52.8, 59.9, 60.0, 67.0)] == \
            [0.037, 0.037, 0.022, 0.022, 0.009, 0.009]
    assert (got.threshold_for("landscape"), got.threshold_for("portrait")) == (0.009, 0.022)
    assert got.describe("landscape", 52.8) == "far_mass 0.022 (portrait: frames under 60 deg across)"
    assert got.describe("portrait", 65.0) == "far_mass 0.009 (landscape: frames at least 60 deg across)"
    assert got.describe("landscape", 40.0) == "far_mass 0.037 (a narrow camera's: frames at most 42 deg across)"
    old = B.UncertaintySpec("far_mass", 0.009, 0.022, narrow_threshold=0.037, narrow_fov_deg=42.0)
    assert (old.threshold_for("landscape", 52.8), old.threshold_for("portrait", 65.0)) == (0.009, 0.022)
    for change, msg in (({"wide_fov_deg": 42.0}, "wide_fov_deg 42 must exceed narrow_fov_deg 42"),
                        ({"wide_fov_deg": 200}, "wide_fov_deg = 200 is out of range")):
        bad = json.loads(json.dumps(meta))
        bad["calibration"]["uncertainty"].update(change)
        with pytest.raises(B.BundleError, match=msg) as err:
            B.parse_meta(bad, need_bytes=False)
        assert "\n" not in str(err.value)


def test_mirror_tta_is_written_only_when_on_and_read_back():
    """``mc.mirror``: absent (older bundles, and mirror off) reads as False."""
    from crossing_assist import bundle as B

    off = B.make_meta(**_typed_parts())
    assert "mirror" not in off["mc"] and B.parse_meta(off, need_bytes=False).mc.mirror is False
    on = B.make_meta(**_typed_parts(mc=McSpec(16, 0.5, mirror=True)))
    assert on["mc"] == {"samples": 16, "p": 0.5, "mirror": True}
    assert B.parse_meta(on, need_bytes=False).mc == McSpec(16, 0.5, True)


@pytest.mark.parametrize("over, words", [
    (dict(mc=McSpec(0, 0.5)), "mc.samples"), (dict(n_actions=5), "actions.n"), (dict(precision="fp16"), "precision"),
])
def test_the_writer_refuses_bad_parts_with_one_line(over, words):
    from crossing_assist import bundle as B

    with pytest.raises(BundleError) as e:
        B.make_meta(**_typed_parts(**over))
    assert words in str(e.value) and "\n" not in str(e.value)


def test_write_replaces_existing_atomically_and_leaves_no_temp(tmp_path):
    write_bundle(tmp_path / "b", FAKE_ONNX, make_meta())
    write_bundle(tmp_path / "b", FAKE_ONNX + b"x" * 10, make_meta(n=4))
    b = read_bundle(tmp_path / "b")
    assert b.actions.n == 4 and b.model_size == len(FAKE_ONNX) + 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b"]


def test_write_refuses_bad_meta_and_keeps_old_bundle(tmp_path):
    write_bundle(tmp_path / "b", FAKE_ONNX, make_meta())
    with pytest.raises(BundleError, match="actions.n"):
        write_bundle(tmp_path / "b", FAKE_ONNX, make_meta(actions={"n": 5, "names": [], "bins": []}))
    assert read_bundle(tmp_path / "b").actions.n == 13
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b"]


def _rewrite(bundle_dir: Path, edit) -> None:
    meta = json.loads((bundle_dir / "bundle.json").read_text())
    edit(meta)
    (bundle_dir / "bundle.json").write_text(json.dumps(meta))


def _one_line_error(bundle_dir, match: str) -> str:
    with pytest.raises(BundleError, match=match) as info:
        read_bundle(bundle_dir)
    msg = str(info.value)
    assert "\n" not in msg and len(msg) < 300
    return msg


def test_missing_folder_json_and_model(tmp_path, bundle_dir):
    _one_line_error(tmp_path / "nope", "not a folder")
    (bundle_dir / "model.onnx").unlink()
    _one_line_error(bundle_dir, "model.onnx is missing")
    (bundle_dir / "bundle.json").unlink()
    _one_line_error(bundle_dir, "bundle.json is missing")


def test_truncated_and_replaced_model(bundle_dir):
    path = bundle_dir / "model.onnx"
    path.write_bytes(FAKE_ONNX[:100])
    _one_line_error(bundle_dir, "truncated")
    path.write_bytes(b"\x00" + FAKE_ONNX[1:])
    _one_line_error(bundle_dir, "not an ONNX model")
    path.write_bytes(FAKE_ONNX[:-1] + b"\xff")
    _one_line_error(bundle_dir, "SHA-256")
    assert read_bundle(bundle_dir, verify_hash=False).model_size == len(FAKE_ONNX)


def test_invalid_json_text(bundle_dir):
    (bundle_dir / "bundle.json").write_text('{"schema_version": 1,')
    _one_line_error(bundle_dir, "not valid JSON")


def test_nan_in_bundle_json_is_refused_as_the_app_refuses_it(bundle_dir):
    """Python's json reads NaN; the app's JSON.parse does not: a hand-edited NaN is one line here too."""
    path = bundle_dir / "bundle.json"
    path.write_text(path.read_text().replace('"metrics": {', '"metrics": {"x": NaN, ', 1))
    assert "NaN" in path.read_text()
    _one_line_error(bundle_dir, "NaN is not JSON")


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda m: m.update(schema_version=5), "schema_version 5 unsupported.*upgrade"),
        (lambda m: m.update(schema_version=0), "schema_version 0 unsupported.*re-export"),
        (lambda m: m.pop("fov_deg"), "missing field 'fov_deg'"),
        (lambda m: m["actions"].update(n=5), "actions.n = 5 invalid; valid: 4, 8, 13"),
        (lambda m: m["actions"].update(n=8), "actions.names .* disagree with the 8-action space"),
        (lambda m: m["actions"]["names"].reverse(), "actions.names"),
        (lambda m: m["actions"]["bins"].__setitem__(3, [4]), "actions.bins disagree"),
        (lambda m: m["input"].update(size=[224]), r"input.size = \[224\] invalid"),
        (lambda m: m["input"].update(size=[0, 224]), r"input.size"),
        (lambda m: m["input"].update(size=[224.0, 224]), r"input.size"),
        (lambda m: m["input"].update(layout="NCHW"), "input.layout = 'NCHW' unsupported"),
        (lambda m: m["input"].update(std=[0.2, 0.0, 0.2]), r"input.std\[1\] = 0.0 is out of range"),
        (lambda m: m["input"]["mean"].pop(), "input.mean must be a list of 3"),
        (lambda m: m["mc"].update(samples=0), "mc.samples = 0 is out of range"),
        (lambda m: m["mc"].update(p=1.0), r"mc.p = 1.0 is out of range"),
        (lambda m: m["mc"].update(mirror=1), "mc.mirror = 1 must be true or false"),
        (lambda m: m["calibration"].update(temperature=-1), "calibration.temperature"),
        (lambda m: m["calibration"]["conformal"].update(coverage=1.0), "calibration.conformal.coverage"),
        (lambda m: m["calibration"]["conformal"].pop("threshold"),
         "missing field 'calibration.conformal.threshold'"),
        (lambda m: m["calibration"]["uncertainty"].update(measure="vibes"),
         "calibration.uncertainty.measure = 'vibes' unknown; valid: entropy"),
        (lambda m: m.update(precision="fp16"), "precision = 'fp16' unknown"),
        (lambda m: m.update(model_file="../x.onnx"), "model_file"),
        (lambda m: m.update(training=[]), "training must be an object"),
        (lambda m: m.update(model_sha256="xyz"), "model_sha256"),
    ],
)
def test_invalid_fields_give_one_line_naming_the_field(bundle_dir, edit, match):
    _rewrite(bundle_dir, edit)
    _one_line_error(bundle_dir, match)


def test_reader_is_torch_free():
    code = "import sys, crossing_assist.bundle; sys.exit(3 if 'torch' in sys.modules or 'onnx' in sys.modules else 0)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


# ----------------------------------------------------------------------------- check_session


def fake_session(meta: dict, *, a: int = 13, input_type: str = "tensor(uint8)", outputs=None):
    outs = outputs or ["probs", "entropy", "mutual_info", "variance", "votes"]
    return SimpleNamespace(
        get_inputs=lambda: [SimpleNamespace(name="frames", type=input_type, shape=["N", "H", "W", 3])],
        get_outputs=lambda: [SimpleNamespace(name=o, shape=["N", a] if o == "probs" else ["N"]) for o in outs],
        get_modelmeta=lambda: SimpleNamespace(
            custom_metadata_map={"bundle_json": json.dumps(embedded_meta(meta)), "schema_version": "1"}),
    )


def test_check_session_accepts_matching_graph(bundle_dir):
    b = read_bundle(bundle_dir)
    check_session(b, fake_session(make_meta()))


def test_check_session_refuses_mismatches(bundle_dir):
    b = read_bundle(bundle_dir)
    with pytest.raises(BundleError, match="graph has 8 actions but bundle.json says 13"):
        check_session(b, fake_session(make_meta(), a=8))
    with pytest.raises(BundleError, match="graph input"):
        check_session(b, fake_session(make_meta(), input_type="tensor(float)"))
    with pytest.raises(BundleError, match="lacks outputs"):
        check_session(b, fake_session(make_meta(), outputs=["probs"]))
    other = make_meta()
    other["input"] = dict(other["input"], size=[160, 160])
    with pytest.raises(BundleError, match=r"^bundle\.json: input\.size\[0\] = 224 disagrees with the model's 160; "
                                          "re-export the bundle$"):
        check_session(b, fake_session(other))
    with pytest.raises(BundleError, match=r"^bundle\.json: actions\.n = 13 disagrees with the model's 4;"):
        check_session(b, fake_session(make_meta(n=4)))


def _edited(edit) -> dict:
    meta = json.loads(json.dumps(make_meta()))
    edit(meta)
    return meta


@pytest.mark.parametrize("edit, line", [
    (lambda m: m["calibration"]["uncertainty"].update(threshold=0.05),
     "calibration.uncertainty.threshold = 0.05 disagrees with the model's 1.2"),
    (lambda m: m["calibration"]["uncertainty"].update(portrait_threshold=2.0),
     "calibration.uncertainty.portrait_threshold = 2.0 disagrees with the model's absent"),
    (lambda m: m["input"]["size"].__setitem__(1, 160), "input.size[1] = 160 disagrees with the model's 224"),
    (lambda m: m.update(fov_deg=100), "fov_deg = 100 disagrees with the model's 90.0"),
    (lambda m: m["mc"].update(mirror=True), "mc.mirror = true disagrees with the model's absent"),
])
def test_check_session_names_the_first_differing_leaf_in_one_short_line(bundle_dir, edit, line):
    """bundle.json hand-edited after export: the line names the leaf and both values (the graph's
    copy holds make_meta()); the app's bundle.js checkEmbedded words it alike."""
    folder = bundle_dir.parent / "edited"
    write_bundle(folder, FAKE_ONNX, _edited(edit))
    with pytest.raises(BundleError) as info:
        check_session(read_bundle(folder), fake_session(make_meta()))
    msg = str(info.value)
    assert msg == f"bundle.json: {line}; re-export the bundle" and len(msg) < 120


def test_check_session_compares_as_python_equality(bundle_dir):
    """1 == 1.0 and key order does not matter: a graph copy written with floats and keys reversed agrees."""
    meta = make_meta()
    graph = json.loads(json.dumps(embedded_meta(meta)), object_pairs_hook=lambda kv: dict(reversed(kv)))
    graph["mc"]["samples"] = 16.0
    graph["input"]["size"] = [224.0, 224.0]
    session = fake_session(meta)
    session.get_modelmeta = lambda: SimpleNamespace(custom_metadata_map={"bundle_json": json.dumps(graph)})
    check_session(read_bundle(bundle_dir), session)
    session.get_modelmeta = lambda: SimpleNamespace(custom_metadata_map={"bundle_json": "[1, 2]"})
    with pytest.raises(BundleError, match="'bundle_json' metadata is not a JSON object"):
        check_session(read_bundle(bundle_dir), session)
