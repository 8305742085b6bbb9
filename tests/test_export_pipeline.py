"""crossing-export end to end on a tiny real checkpoint and a tiny labelled dataset:
calibrated bundle, onnxruntime predictions, graph/json mismatches, CLI errors."""

import dataclasses
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from export_toy import tiny_policy

from crossing_assist.bundle import BundleError, embedded_meta, read_bundle
from crossing_assist.data_tools.images import load_frame, save_rgb
from crossing_assist.data_tools.manifest import Row, write_manifest
from crossing_assist.conformal import bundle_conformal_report
from crossing_assist.inference import open_session, predict, predict_bundle
from crossing_assist.export.exporter import ExportConfig, ExportError, export_bundle
from crossing_assist.models.checkpoint import save_checkpoint

N_ACTIONS = 4


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    root = tmp_path_factory.mktemp("export")
    rng = np.random.default_rng(0)
    rows = []
    for i in range(30):
        label = int(rng.integers(1, 13))
        img = np.clip(rng.integers(0, 256, (1, 48, 3)) + rng.integers(-40, 40, (40, 48, 3)), 0, 255).astype(np.uint8)
        img[:, int((label - 0.5) / 12 * 48)] = 255  # a bright column at the goal
        save_rgb(root / "data" / f"f{i}.png", img)
        rows.append(Row(image=f"f{i}.png", label=label, far_x=(label - 0.5) / 12, source=f"vid:{i % 3}",
                        split="val", votes={}, flags=()))
    write_manifest(root / "data", rows)
    policy = tiny_policy(N_ACTIONS)
    save_checkpoint(root / "run" / "weights" / "best.pt", policy, {"metrics": {"val": {"accuracy": 0.25}}})
    cfg = ExportConfig(run=str(root / "run"), out=str(root / "bundle"), samples=8, calib_data=str(root / "data"),
                       batch=8, parity_frames=4, progress=False, min_calib=2)   # 30 toy frames
    result = export_bundle(cfg, log=lambda m: None)
    return root, result


def test_export_writes_a_calibrated_valid_bundle(work):
    root, res = work
    b = read_bundle(root / "bundle")
    assert res.path == root / "bundle" and res.size == b.model_size
    assert b.actions.n == N_ACTIONS and b.input.size == (32, 32) and b.mc.samples == 8 and b.mc.p == 0.5
    assert b.precision == "fp32" and b.package_version == "0.1.0"
    c = b.calibration
    assert c.conformal.n_frames == 30 and 0 < c.conformal.threshold <= 1
    assert c.temperature > 0 and c.uncertainty.measure == "entropy" and c.uncertainty.threshold > 0
    assert res.parity_max_abs < 1e-4
    full = b.metrics["full_split"]
    assert full["n"] == 30 and 0 <= full["coverage"] <= 1 and "majority_accuracy" in full
    cross = b.metrics["cross_fit"]  # one fold per source, each measured once, with its own calibration
    assert [f["sources"] for f in cross["folds"]] == [["vid:0"], ["vid:1"], ["vid:2"]]
    assert [f["n"] for f in cross["folds"]] == [10, 10, 10] and cross["n"] == 30
    assert cross["coverage"] == pytest.approx(np.mean([f["coverage"] for f in cross["folds"]]))
    assert len({f["threshold"] for f in cross["folds"]}) > 1
    assert b.training["backbone"] == "squeezenet1_1" and b.provenance["created"]
    assert sorted(p.name for p in root.iterdir()) == ["bundle", "data", "run"]  # no temp folders left


def test_conformal_threshold_is_fitted_on_the_shipped_graph(work):
    """The threshold was fitted on the bundle's own onnxruntime outputs for every labelled
    frame, so in-sample its sets reach the target coverage."""
    root, _ = work
    b = read_bundle(root / "bundle")
    assert b.metrics["full_split"]["coverage"] >= 0.9


def test_graph_metadata_carries_the_bundle_facts(work):
    root, _ = work
    bundle, sess = open_session(root / "bundle")
    props = sess.get_modelmeta().custom_metadata_map
    assert json.loads(props["bundle_json"]) == embedded_meta(bundle.raw)
    assert props["schema_version"] == "3" and bundle.geometry.view_crop == (bundle.geometry.fit == "letterbox")
    # letterbox models state the 4:3 sensor camera_fov_deg describes: 9:16 video gets its crop's FOV
    assert bundle.geometry.sensor_aspect == (4 / 3 if bundle.geometry.fit == "letterbox" else None)


def test_predict_bundle_is_random_and_well_formed(work):
    root, _ = work
    rng = np.random.default_rng(5)
    images = [rng.integers(0, 256, (40, 48, 3), dtype=np.uint8) for _ in range(3)] + \
             [rng.integers(0, 256, (64, 30, 3), dtype=np.uint8)]
    bundle, sess = open_session(root / "bundle")
    a = predict(sess, bundle.actions.n, images)
    b = predict(sess, bundle.actions.n, images)
    assert a["probs"].shape == (4, N_ACTIONS) and a["votes"].shape == (4, N_ACTIONS) and a["entropy"].shape == (4,)
    np.testing.assert_allclose(a["probs"].sum(1), 1, atol=1e-5)
    assert np.abs(a["probs"] - b["probs"]).max() > 1e-5 and (a["variance"] > 0).any()
    # onnxruntime seeds unseeded random ops identically in every new session: a fresh session
    # replays the same masks (documented in docs/export.md).
    np.testing.assert_array_equal(predict_bundle(root / "bundle", images)["probs"], a["probs"])
    with pytest.raises(ValueError, match="image 0"):
        predict_bundle(root / "bundle", [np.zeros((8, 8), np.uint8)])


def _copy(root, name):
    dst = root / name
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(root / "bundle", dst)
    return dst


def _edit(bundle_dir, edit):
    meta = json.loads((bundle_dir / "bundle.json").read_text())
    edit(meta)
    (bundle_dir / "bundle.json").write_text(json.dumps(meta))


def _one_line(exc_info):
    msg = str(exc_info.value)
    assert "\n" not in msg
    return msg


def test_json_disagreeing_with_graph_action_count(work):
    root, _ = work
    d = _copy(root, "wrong_actions")
    from crossing_assist.actions import get_space

    s = get_space(13)
    _edit(d, lambda m: m.update(actions={"n": 13, "names": list(s.names), "bins": [list(g) for g in s.groups]}))
    read_bundle(d)  # the json alone is valid ...
    with pytest.raises(BundleError, match="4 actions but bundle.json says 13") as info:
        open_session(d)  # ... but it disagrees with the graph
    _one_line(info)


def test_json_disagreeing_with_graph_input_size(work):
    root, _ = work
    d = _copy(root, "wrong_size")
    _edit(d, lambda m: m["input"].update(size=[224, 224]))
    with pytest.raises(BundleError, match=r"bundle\.json: input\.size\[\d\] = 224 disagrees with the model's") as info:
        predict_bundle(d, [np.zeros((32, 32, 3), np.uint8)])
    _one_line(info)


def test_truncated_and_missing_model(work):
    root, _ = work
    d = _copy(root, "truncated")
    data = (d / "model.onnx").read_bytes()
    (d / "model.onnx").write_bytes(data[: len(data) // 2])
    with pytest.raises(BundleError, match="truncated") as info:
        open_session(d)
    _one_line(info)
    (d / "model.onnx").unlink()
    with pytest.raises(BundleError, match="missing"):
        open_session(d)


def test_gate_scales_per_orientation(work, tmp_path):
    """--gate-scale and --gate-scale-portrait multiply the one fitted threshold into a landscape
    and a portrait threshold; without the portrait scale the bundle has no portrait threshold
    and portrait frames use the landscape one."""
    root, _ = work
    fitted = read_bundle(root / "bundle").calibration.uncertainty
    assert fitted.portrait_threshold is None and fitted.threshold_for("portrait") == fitted.threshold
    cfg = ExportConfig(run=str(root / "run"), out=str(tmp_path / "b"), samples=8, calib_data=str(root / "data"),
                       batch=8, parity_frames=4, progress=False, gate_scale=0.5, gate_scale_portrait=1.5, min_calib=2)
    export_bundle(cfg, log=lambda m: None)
    u = read_bundle(tmp_path / "b").calibration.uncertainty
    assert u.threshold == pytest.approx(0.5 * fitted.threshold, rel=1e-6)
    assert u.portrait_threshold == pytest.approx(1.5 * fitted.threshold, rel=1e-6)
    assert u.threshold_for("portrait") == u.portrait_threshold and u.threshold_for("landscape") == u.threshold
    assert u.fitted_threshold == pytest.approx(fitted.threshold, rel=1e-6)   # recorded for later re-scaling


def test_the_seed_makes_an_export_reproducible(work, tmp_path):
    """The seed draws the dropout masks of PyTorch (cross-fitting) and of onnxruntime (the shipped
    graph's fits and metrics): the same checkpoint and seed give the same bundle.json figures,
    another seed other ones."""
    root, _ = work

    def export(name, seed):
        export_bundle(ExportConfig(run=str(root / "run"), out=str(tmp_path / name), samples=8, seed=seed,
                                   calib_data=str(root / "data"), batch=8, parity_frames=4, progress=False, min_calib=2),
                      log=lambda m: None)
        b = read_bundle(tmp_path / name)
        return b.calibration, b.metrics["full_split"], b.metrics["cross_fit"]

    first = export("a", 1)
    again, other = export("b", 1), export("c", 2)
    assert again == first
    assert other[1]["nll"] != first[1]["nll"]                  # onnxruntime's masks (the graph's own metrics)
    assert other[2]["folds"] != first[2]["folds"]              # PyTorch's (the cross-fitted calibration)
    with pytest.raises(ExportError, match="--seed -1"):
        ExportConfig(run="r", out="o", seed=-1)


def test_mirror_export_writes_the_flag_and_its_graph_is_mirror_equivariant(work, tmp_path):
    """--mirror: bundle.json says so, and (deterministic graph, p = 0) the mirrored frame gets the
    mirrored actions' probabilities (here 4 actions: left <-> right)."""
    root, _ = work
    cfg = ExportConfig(run=str(root / "run"), out=str(tmp_path / "m"), samples=1, p=0.0, calib_data=str(root / "data"),
                       batch=8, parity_frames=4, progress=False, mirror=True, min_calib=2)
    export_bundle(cfg, log=lambda m: None)
    b = read_bundle(tmp_path / "m")
    assert b.mc.mirror is True and read_bundle(root / "bundle").mc.mirror is False
    frame = np.random.default_rng(3).integers(0, 256, (40, 48, 3), dtype=np.uint8)
    p, q = (predict_bundle(tmp_path / "m", [f])["probs"][0] for f in (frame, np.ascontiguousarray(frame[:, ::-1])))
    perm = [b.space.mirror_action(a) for a in range(b.space.n)]
    assert perm != list(range(b.space.n))
    np.testing.assert_allclose(q, p[perm], atol=1e-5)


def test_config_rejects_bad_options():
    with pytest.raises(ExportError, match="--gate-scale-portrait 0.0"):
        ExportConfig(run="r", out="o", gate_scale_portrait=0.0)
    with pytest.raises(ExportError, match="^--int8 needs --calib-data"):
        ExportConfig(run="r", out="o", int8=True)
    with pytest.raises(ExportError, match="^--gate-scale / --gate-scale-portrait need --calib-data"):
        ExportConfig(run="r", out="o", gate_scale=2.0)   # was ignored: the threshold as if not given
    with pytest.raises(ExportError, match="need --calib-data"):
        ExportConfig(run="r", out="o", gate_scale_portrait=1.5)
    with pytest.raises(ExportError, match="--p 1.0"):
        ExportConfig(run="r", out="o", p=1.0)
    with pytest.raises(ExportError, match="--view-zoom 0.5; valid: 1..4"):
        ExportConfig(run="r", out="o", view_zoom=0.5)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "crossing_assist.export.cli", *args],
                          capture_output=True, text=True, timeout=300)


def test_cli_user_errors_are_one_line(tmp_path):
    proc = _cli("--run", str(tmp_path / "nope"), "--out", str(tmp_path / "b"))
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and "best.pt" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not (tmp_path / "b").exists()


@pytest.mark.slow
def test_cli_exports_int8_and_reports(work, tmp_path):
    root, _ = work
    proc = _cli("--run", str(root / "run"), "--out", str(tmp_path / "b8"), "--samples", "4",
                "--calib-data", str(root / "data"), "--min-calib", "2", "--int8", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"bundle written: {tmp_path / 'b8'} (") and "MB" in proc.stdout
    assert "int8 vs fp32" in proc.stderr and "parity" in proc.stderr
    b = read_bundle(tmp_path / "b8")
    assert b.precision == "int8" and b.metrics["int8_vs_fp32"]["size_ratio"] < 1
    out = predict_bundle(tmp_path / "b8", [np.zeros((40, 48, 3), np.uint8)])
    assert (out["mutual_info"] >= 0).all()


def test_cli_flags_cover_every_config_field():
    from dataclasses import fields

    from crossing_assist.export.cli import build_parser

    parser = build_parser()
    dests = {a.dest for a in parser._actions}
    assert {f.name for f in fields(ExportConfig)} <= dests
    args = parser.parse_args(["--run", "r", "--out", "o"])
    for f in fields(ExportConfig):
        if f.name not in ("run", "out"):
            assert getattr(args, f.name) == f.default, f.name


def test_bundle_conformal_report_uses_the_bundles_threshold(work):
    root, _ = work
    b = read_bundle(root / "bundle")
    probs = np.full((4, N_ACTIONS), 1 / N_ACTIONS, np.float32)
    probs[:, 1] += 0.3
    probs[:, 2] -= 0.3
    rep = bundle_conformal_report(root / "bundle", probs, np.array([1, 2, 1, 0]))
    assert rep["target_coverage"] == 0.9 and rep["calibration_frames"] == 30
    assert rep["threshold"] == b.calibration.conformal.threshold
    in_set = probs >= b.calibration.conformal.threshold
    assert rep["coverage"] == pytest.approx(np.mean([in_set[0, 1], in_set[1, 2], in_set[2, 1], in_set[3, 0]]))


def test_crossing_eval_on_a_bundle_reports_metrics_and_coverage(work, tmp_path):
    """What a user runs to check what they ship: crossing-eval --bundle, through onnxruntime."""
    root, _ = work
    out = tmp_path / "eval"
    r = subprocess.run([sys.executable, "-m", "crossing_assist.models.cli", "eval", "--bundle", str(root / "bundle"),
                        "--data", str(root / "data"), "--split", "val", "--out", str(out), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "conformal sets: coverage" in r.stdout
    m = json.loads((out / "metrics.json").read_text())
    assert m["source"] == "bundle" and m["n"] == 30
    b = read_bundle(root / "bundle")
    c = m["conformal"]
    assert c["n"] == 30 and c["threshold"] == b.calibration.conformal.threshold and c["target_coverage"] == 0.9
    assert 0.0 <= c["coverage"] <= 1.0 and sum(c["size_hist"]) == 30
    for name in ("confusion_matrix.png", "reliability.png"):
        assert (out / name).stat().st_size > 0


def test_export_without_labelled_data_is_honestly_uncalibrated(work, tmp_path):
    root, _ = work
    res = export_bundle(ExportConfig(run=str(root / "run"), out=str(tmp_path / "u"), samples=4, parity_frames=2,
                                     progress=False), log=lambda m: None)
    b = read_bundle(tmp_path / "u")
    assert b.calibration.temperature == 1.0 and b.calibration.conformal.threshold == 0.0
    assert b.calibration.conformal.n_frames == 0 and "cross_fit" not in b.metrics
    assert any("not calibrated" in n for n in res.notes)


def test_letterbox_exports_state_the_phone_sensor():
    """The exported geometry: letterbox models get view_crop and sensor_aspect 4:3 (so 9:16 video
    gets its crop's FOV); stretch models neither (today's rule)."""
    from types import SimpleNamespace

    from crossing_assist.export.exporter import _geometry
    from crossing_assist.export.graph import GraphSpec

    for fit, aspect in (("letterbox", 4 / 3), ("stretch", None)):
        g = _geometry(SimpleNamespace(fov_deg=67.0), GraphSpec(size=(32, 32), mean=(0.5,) * 3, std=(0.25,) * 3, fit=fit))
        assert g.sensor_aspect == aspect and g.view_crop == (fit == "letterbox")
        assert g.to_json().get("sensor_aspect") == aspect


def test_view_zoom_makes_a_schema4_letterbox_geometry_and_is_refused_for_a_stretch_model(work, tmp_path):
    """--view-zoom Z: a letterbox model's geometry carries view_zoom (schema 4); a stretched model
    (the toy run) is refused in one line before any calibration, and nothing is written."""
    from types import SimpleNamespace

    from crossing_assist.bundle import schema_for
    from crossing_assist.export.exporter import _geometry
    from crossing_assist.export.graph import GraphSpec

    spec = GraphSpec(size=(32, 32), mean=(0.5,) * 3, std=(0.25,) * 3, fit="letterbox")
    g = _geometry(SimpleNamespace(fov_deg=67.0), spec, 1.3)
    assert g.view_zoom == 1.3 and g.view_crop and g.to_json()["view_zoom"] == 1.3 and schema_for(g) == 4
    assert schema_for(_geometry(SimpleNamespace(fov_deg=67.0), spec)) == 3
    root, _ = work
    cfg = ExportConfig(run=str(root / "run"), out=str(tmp_path / "z"), samples=8, calib_data=str(root / "data"),
                       batch=8, parity_frames=4, progress=False, view_zoom=1.3)
    with pytest.raises(ExportError, match="--view-zoom 1.3: the checkpoint stretches frames"):
        export_bundle(cfg, log=lambda m: None)
    assert not (tmp_path / "z").exists()


def test_far_mass_export_fits_its_threshold_on_the_graphs_probabilities(work, tmp_path):
    """``--measure far_mass``: the bundle's gate reads the probability beyond one strip of the
    argmax, its threshold fitted (P(correct | far mass) = 1/2) on the far masses of the shipped
    graph's outputs, inside their range; the runtime gates with it. ``variance`` has no export fit."""
    from crossing_assist.runtime import belief as bf
    from crossing_assist.runtime.engine import Engine

    root, _ = work
    cfg = ExportConfig(run=str(root / "run"), out=str(tmp_path / "b"), samples=8, calib_data=str(root / "data"),
                       batch=8, parity_frames=4, progress=False, seed=1, min_calib=2)
    export_bundle(dataclasses.replace(cfg, measure="far_mass"), log=lambda m: None)
    u = read_bundle(tmp_path / "b").calibration.uncertainty
    assert u.measure == "far_mass" and 0 < u.threshold < 1 and u.fitted_threshold == pytest.approx(u.threshold)
    engine = Engine(tmp_path / "b")
    frame = np.asarray(load_frame(root / "data" / "f0.png"))
    p = engine.predict(frame)
    assert p.ok and p.uncertainty == pytest.approx(bf.far_mass(p.probs)) and p.uncertainty != pytest.approx(p.entropy)
    assert engine.decision_config().measure == "far_mass" and engine.decision_config().threshold == u.threshold
    with pytest.raises(ExportError, match="--measure 'variance'; valid: entropy, mutual_info, far_mass"):
        dataclasses.replace(cfg, measure="variance")


def test_calibration_frames_are_what_the_runtime_gives_the_graph(tmp_path):
    """The export calibrates on each frame as Engine.predict feeds it: a portrait photo's rows
    cropped to the training camera's view at the portrait FOV, a 4:3 landscape photo whole; a
    frame too narrow for any FOV is one clear ExportError."""
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest
    from crossing_assist.export.exporter import ExportError, load_labelled
    from crossing_assist.geometry import Geometry, view_rows

    def dataset(shapes, label=6):
        root = tmp_path / f"d{len(list(tmp_path.iterdir()))}"
        (root / "images").mkdir(parents=True)
        rows = []
        for i, (h, w) in enumerate(shapes):
            save_rgb(root / "images" / f"{i}.png", np.full((h, w, 3), 90, np.uint8))
            rows.append(Row(image=f"images/{i}.png", label=label, far_x=0.45 if label else None, source=f"s:{i}",
                            split="val"))
        write_manifest(root, rows)
        return str(root)

    geo = Geometry(fit="letterbox", camera_fov_deg=(67.0, 53.0), train_fov_deg=67.0, view_crop=True, sensor_aspect=4 / 3)
    d = load_labelled(dataset([(128, 96), (96, 128)]), "val", 13, progress=False, geometry=geo, canvas=(36, 48))
    _, rows = view_rows(128, 96, 53.0, (36, 48), 67.0)
    assert rows < 128 and [im.shape for im in d.images] == [(rows, 96, 3), (96, 128, 3)]
    raw = load_labelled(dataset([(128, 96), (96, 128)]), "val", 13, progress=False)
    assert raw.images[0].shape == (128, 96, 3)
    with pytest.raises(ExportError, match="calib-data"):
        load_labelled(dataset([(160, 32), (96, 128)]), "val", 13, progress=False, geometry=geo, canvas=(36, 48))
    # negatives only (crossing-data negatives' output): calibrated silently before, temperature at its clip
    with pytest.raises(ExportError, match="no frame with a crossing label"):
        load_labelled(dataset([(96, 128)] * 3, label=0), "val", 13, progress=False)


def test_the_calibration_log_says_when_its_folds_are_not_held_out_by_source(work, tmp_path):
    """A researcher calibrating on one video: its folds are contiguous blocks of that one source,
    and the log says so instead of naming the same source five times 'by source'."""
    root, _ = work
    from dataclasses import replace

    from crossing_assist.data_tools.manifest import read_manifest

    rows = [replace(r, source="vid:one") for r in read_manifest(root / "data").rows]
    (tmp_path / "one").mkdir()
    for r in rows:
        (tmp_path / "one" / r.image).symlink_to(root / "data" / r.image)
    write_manifest(tmp_path / "one", rows)
    lines = []
    for data, out in ((root / "data", "several"), (tmp_path / "one", "single")):
        logged = []
        export_bundle(ExportConfig(run=str(root / "run"), out=str(tmp_path / out), samples=8, calib_data=str(data),
                                   batch=8, parity_frames=4, progress=False, min_calib=2), log=logged.append)
        lines.append(next(m for m in logged if m.startswith("held-out conformal coverage")))
    several, single = lines
    assert "folds by source: vid:" in several
    assert "contiguous blocks of the one source vid:one (not held out by source" in single
    assert "block 1 " in single and "by source:" not in single
