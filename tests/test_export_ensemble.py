"""crossing-export ensemble: several bundles' graphs as one, their MC samples pooled; the merged
bundle's plays are the members' plays averaged (what choose_gate.py --ensemble replays)."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import onnx
import pytest
from runtime_toy import bar_dataset, bar_frame, graph_outputs, make_toy_bundle, seeded

from crossing_assist.actions import UNKNOWN, bin_center_x
from crossing_assist.bundle import read_bundle
from crossing_assist.export.ensemble import merge_graphs, share_alike
from crossing_assist.inference import predict_bundle
from crossing_assist.runtime.engine import Engine
from crossing_assist.runtime.demo import DEFAULT_BUNDLE
from crossing_assist.runtime.listen import Listener, summarise

#: Deterministic toys (no dropout, no noise) that see the same bar with different sharpness, and
#: one that puts its unknown logit high: members that disagree on how sure to be.
SHARP, SOFT, DOUBTFUL = dict(gain=12.0), dict(gain=3.0), dict(gain=6.0, unknown_logit=2.0)


def _det(folder, **kw):
    return make_toy_bundle(folder, drop_p=0.0, noise=0.0, samples=2, **kw)


def _entropy(p):
    return -(p * np.log(np.maximum(p, 1e-30))).sum(-1)


def _run(bundle, frames):
    return predict_bundle(bundle, list(frames), batch=8)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "crossing_assist.export", "ensemble", *map(str, args), "--quiet",
                           "--min-calib", "2"],   # toy calibration sets
                          capture_output=True, text=True)


def test_merged_graph_pools_the_members_samples_exactly(tmp_path):
    """Each output of the merged graph is what one graph summarising all members' samples gives:
    the mean probabilities, their entropy, the disagreement between (and within) members as mutual
    information and variance, the mean votes."""
    members = [_det(tmp_path / name, **kw) for name, kw in (("a", SHARP), ("b", SOFT), ("c", DOUBTFUL))]
    frames = [bar_frame(bin_center_x(s)) for s in (1, 5, 12)] + [bar_frame(None, noise=0.4)]
    outs = [_run(m, frames) for m in members]
    merged = merge_graphs([onnx.load(str(read_bundle(m).model_path)) for m in members])
    import onnxruntime as ort

    got = dict(zip(("probs", "entropy", "mutual_info", "variance", "votes"),
                   ort.InferenceSession(merged.SerializeToString()).run(None, {"frames": np.stack(frames)})))
    probs = np.stack([o["probs"] for o in outs])          # [members, N, A]; each member's samples agree
    mean = probs.mean(0)
    np.testing.assert_allclose(got["probs"], mean, atol=1e-6)
    np.testing.assert_allclose(got["entropy"], _entropy(mean), atol=1e-5)
    np.testing.assert_allclose(got["mutual_info"], _entropy(mean) - _entropy(probs).mean(0), atol=1e-5)
    np.testing.assert_allclose(got["variance"], (probs ** 2).mean(0) - mean ** 2, atol=1e-6)
    np.testing.assert_allclose(got["votes"], np.mean([o["votes"] for o in outs], 0), atol=1e-6)
    assert got["mutual_info"].min() > 1e-5      # each member alone is sure (0); together they disagree
    assert (got["probs"].argmax(1)[:3] == [1, 5, 12]).all()


def _ops(model, op):
    return sum(n.op_type == op for n in model.graph.node)


def test_merged_graph_runs_what_its_members_compute_alike_once(tmp_path):
    """Members that fit the frame alike share those nodes in the merged graph (the toys' resize and
    normalisation; the default's frozen blocks); each keeps its own random draws, even two members
    alike (their dropout masks stay two sets), and the outputs are those of the graph merged side
    by side, bit for bit."""
    noisy = dict(drop_p=0.3, noise=0.5, samples=4)
    members = [make_toy_bundle(tmp_path / name, gain=gain, **noisy) for name, gain in (("a", 12.0), ("b", 12.0), ("c", 3.0))]
    models = [onnx.load(str(read_bundle(m).model_path)) for m in members]
    apart, shared = merge_graphs(models, share=False), merge_graphs(models)
    assert len(shared.graph.node) < len(apart.graph.node)
    assert (_ops(apart, "Resize"), _ops(shared, "Resize")) == (3, 1)        # the frame fitted once
    assert (_ops(apart, "Tile"), _ops(shared, "Tile")) == (3, 2)            # a and b alike up to their draws
    assert _ops(shared, "RandomUniformLike") == _ops(apart, "RandomUniformLike") == 6   # each member's own
    assert share_alike(shared) == 0                                         # nothing left computed twice
    frames = [bar_frame(bin_center_x(s)) for s in (2, 7, 11)] + [bar_frame(None, noise=0.4)]
    for got, want in zip(graph_outputs(seeded(shared), frames), graph_outputs(seeded(apart), frames)):
        np.testing.assert_array_equal(got, want)


def test_share_alike_knows_weights_by_their_values_not_their_names():
    """Two members' weights under their own names (``m0/w``, ``m1/w``) are one weight when their
    values agree (the members' frozen blocks), two when they differ; what reads a graph output
    stays."""
    from onnx import TensorProto, helper, numpy_helper

    w = np.arange(6, dtype=np.float32).reshape(3, 2)
    weights = [numpy_helper.from_array(v, name) for name, v in (("m0/w", w), ("m1/w", w.copy()), ("m2/w", w + 1))]
    nodes = [helper.make_node("MatMul", ["frames", f"m{i}/w"], [f"m{i}/y"]) for i in range(3)]
    nodes += [helper.make_node("Relu", [f"m{i}/y"], [f"m{i}/r"]) for i in range(3)]
    nodes += [helper.make_node("Sum", ["m0/r", "m1/r", "m2/r"], ["out"]), helper.make_node("Relu", ["m0/y"], ["kept"])]
    graph = helper.make_graph(nodes, "g", [helper.make_tensor_value_info("frames", TensorProto.FLOAT, [1, 3])],
                              [helper.make_tensor_value_info(n, TensorProto.FLOAT, [1, 2]) for n in ("out", "kept")],
                              initializer=weights)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    before = graph_outputs(model, [np.array([1.0, -2.0, 3.0], np.float32)])
    assert share_alike(model) == 2                     # m1's MatMul and Relu; "kept" names an output
    assert [n.op_type for n in model.graph.node] == ["MatMul", "MatMul", "Relu", "Relu", "Sum", "Relu"]
    assert sorted(t.name for t in model.graph.initializer) == ["m0/w", "m2/w"]
    onnx.checker.check_model(model)
    for got, want in zip(graph_outputs(model, [np.array([1.0, -2.0, 3.0], np.float32)]), before):
        np.testing.assert_array_equal(got, want)


def test_the_default_bundle_runs_what_its_members_share_once():
    """The shipped ensemble's graph computes nothing twice (its members' frozen blocks run once)
    and draws each member's dropout masks apart."""
    bundle = read_bundle(DEFAULT_BUNDLE)
    model = onnx.load(str(bundle.model_path))
    assert bundle.mc.members == 3 and _ops(model, "RandomUniformLike") == 3
    assert share_alike(model) == 0


def test_ensemble_bundle_refits_its_thresholds_and_runs_in_the_runtime(tmp_path):
    """``crossing-export ensemble``: a bundle whose mc.members says how many, its members' training
    facts kept, its gate threshold fitted again through the merged graph; the runtime runs it as
    any bundle, and its plays are the members' plays averaged frame by frame."""
    a, b = _det(tmp_path / "a", **SHARP), _det(tmp_path / "b", **SOFT)
    data = bar_dataset(tmp_path / "data", n=12)
    r = _cli(a, b, "--out", tmp_path / "ens", "--calib-data", data)
    assert r.returncode == 0, r.stderr
    assert "ensemble bundle written" in r.stdout and "2 members" in r.stdout
    ens = read_bundle(tmp_path / "ens")
    assert ens.mc.members == 2 and ens.mc.samples == 2
    assert [m["bundle"] for m in ens.training["ensemble"]] == [str(a), str(b)]
    u = ens.calibration.uncertainty
    assert u.measure == "far_mass" and u.threshold == ens.calibration.uncertainty.fitted_threshold > 0
    assert ens.metrics["full_split"]["n"] == 12 and len(ens.metrics["members"]) == 2
    embedded = json.loads(dict((p.key, p.value) for p in onnx.load(str(ens.model_path)).metadata_props)["bundle_json"])
    assert embedded["mc"]["members"] == 2                     # the graph carries the same facts

    plays = []
    for bundle in (a, b, tmp_path / "ens"):
        lis = Listener(Engine(bundle), seconds=0.3)
        for strip in (2, 7, 11):
            lis.add(bar_frame(bin_center_x(strip)), strip)
        lis.add(bar_frame(None, noise=0.4), UNKNOWN)
        lis.save(tmp_path / f"{bundle.name}.npz")
        plays.append(lis)
    averaged, _ = Listener.average(Engine(tmp_path / "ens"), [tmp_path / "a.npz", tmp_path / "b.npz"])
    for clip, merged in zip(averaged.clips, plays[2].clips):
        for p, q in zip(clip, merged):
            np.testing.assert_allclose(p.probs, q.probs, atol=1e-6)
            assert p.uncertainty == pytest.approx(q.uncertainty, abs=1e-6) and p.action == q.action
    for t in (None, 0.01, 0.2):
        for h, g in zip(averaged.heard(t), plays[2].heard(t)):
            assert (h.on, h.strip, h.label) == (g.on, g.strip, g.label)
            assert h.heading_deg == pytest.approx(g.heading_deg, abs=1e-6)
    assert [h.on for h in averaged.heard(0.2)] == [True, True, True, False]


def test_ensemble_refuses_members_exported_differently_or_alone(tmp_path):
    a, data = _det(tmp_path / "a", **SHARP), bar_dataset(tmp_path / "data", n=6)
    other = make_toy_bundle(tmp_path / "other", drop_p=0.0, noise=0.0, samples=4)
    wide = make_toy_bundle(tmp_path / "wide", drop_p=0.0, noise=0.0, samples=2, size=(24, 60))
    cases = [((a,), "an ensemble needs at least 2"),
             ((a, other), "differs from .* in 'mc'"),
             ((a, wide), "differs from .* in 'input'"),
             ((a, tmp_path / "missing"), "is not a folder")]
    for members, message in cases:
        r = _cli(*members, "--out", tmp_path / "ens", "--calib-data", data)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert r.stderr.startswith("error:") and re.search(message, r.stderr), r.stderr
        assert not (tmp_path / "ens").exists()
    assert _cli(a, _det(tmp_path / "b", **SOFT), "--out", tmp_path / "ens", "--calib-data", data).returncode == 0
    r = _cli(tmp_path / "ens", other, "--out", tmp_path / "ens2", "--calib-data", data)   # an ensemble: but for
    assert r.returncode == 2 and re.search("differs from .* in 'mc'", r.stderr), r.stderr  # its members, alike


def test_an_ensemble_as_a_member_counts_as_its_members(tmp_path):
    """A member added to an ensemble bundle (whose members' own bundles may be gone): the result is
    the ensemble of all the members merged at once, output for output, and its bundle.json lists
    them all."""
    a, b, c = (_det(tmp_path / name, **kw) for name, kw in (("a", SHARP), ("b", SOFT), ("c", DOUBTFUL)))
    data = bar_dataset(tmp_path / "data", n=12)
    assert _cli(a, b, "--out", tmp_path / "ab", "--calib-data", data).returncode == 0
    r = _cli(tmp_path / "ab", c, "--out", tmp_path / "abc", "--calib-data", data)
    assert r.returncode == 0, r.stderr
    assert "3 members" in r.stdout
    abc = read_bundle(tmp_path / "abc")
    assert abc.mc.members == 3
    assert [m["bundle"] for m in abc.training["ensemble"]] == [str(a), str(b), str(c)]
    assert len(abc.metrics["members"]) == len(abc.raw["provenance"]["members"]) == 3
    frames = [bar_frame(bin_center_x(s)) for s in (1, 6, 12)] + [bar_frame(None, noise=0.4)]
    at_once = merge_graphs([onnx.load(str(read_bundle(m).model_path)) for m in (a, b, c)])
    for got, want in zip(graph_outputs(onnx.load(str(abc.model_path)), frames), graph_outputs(at_once, frames)):
        np.testing.assert_allclose(got, want, atol=1e-7)
    assert len(onnx.load(str(abc.model_path)).graph.node) == len(at_once.graph.node)   # the old pooling dropped


def test_average_refuses_plays_of_other_clips(tmp_path):
    a = _det(tmp_path / "a", **SHARP)
    for name, strips in (("one", (2, 7)), ("two", (2, 8))):
        lis = Listener(Engine(a), seconds=0.2)
        for s in strips:
            lis.add(bar_frame(bin_center_x(s)), s)
        lis.save(tmp_path / f"{name}.npz")
    with pytest.raises(ValueError, match="did not play the clips"):
        Listener.average(Engine(a), [tmp_path / "one.npz", tmp_path / "two.npz"])


def test_choose_gate_ensemble_curves_are_the_averaged_plays_swept(tmp_path):
    """choose_gate.py --ensemble: one photographer's curve for the ensemble of two runs' folds is the
    sweep of their saved plays averaged (no model runs), cached beside the first run's fold."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import choose_gate as cg

    folds = []
    for run, kw in (("run0", SOFT), ("run1", dict(gain=2.0))):
        fold = tmp_path / run / "fold-src_x"
        _det(fold / "bundle", **kw)
        lis = Listener(Engine(fold / "bundle"), seconds=0.3)
        for strip in (1, 4, 9, 12):
            lis.add(bar_frame(bin_center_x(strip)), strip)
        lis.add(bar_frame(None, noise=0.4), UNKNOWN)
        lis.save(fold / "listened_5.npz", in_view=np.arange(4))
        folds.append((fold, "src:x"))

    curves = cg.ensemble_curves(folds, 5, 0, 0, False, None, cg.GRID, 1.0, "far_mass")
    averaged, _ = Listener.average(Engine(folds[0][0] / "bundle"), [f / "listened_5.npz" for f, _ in folds], "far_mass")
    land = curves["landscape"]
    assert (land["frames"], land["no_crossing_frames"], land["goal_in_view_frames"]) == (4, 1, 4)
    for point in land["curve"]:
        assert point["beacon_on"] == cg.sweep_point(averaged.heard(point["scale"] * cg.FAR_MASS_REFERENCE),
                                                    list(range(4)))["beacon_on"]
    assert len({p["beacon_on"] for p in land["curve"]}) > 1          # the sweep moves the beacon
    cached = folds[0][0] / f"gate_curve_5{'' if cg.GRID == 8 else '_grid8'}_far_mass_ensemble2.json"
    assert json.loads(cached.read_text()) == json.loads(json.dumps(land))
    (folds[1][0] / "listened_5.npz").unlink()                        # read from the cache now
    assert cg.ensemble_curves(folds, 5, 0, 0, False, None, cg.GRID, 1.0, "far_mass")["landscape"] == json.loads(cached.read_text())


def test_fresh_check_chooses_on_the_draw_and_measures_the_other_photos(tmp_path):
    """scripts/fresh_check.py: the threshold is chosen on choose_gate.py's draw of N photos a
    photographer (the same indices) and measured on every other saved play, the runs' plays averaged."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import choose_gate as cg
    import fresh_check as fc

    strips, n_neg = (1, 2, 4, 6, 7, 9, 11, 12), 3
    folds = []
    for run, kw in (("run0", SOFT), ("run1", dict(gain=2.0))):
        fold = tmp_path / run / "fold-src_x"
        _det(fold / "bundle", **kw)
        lis = Listener(Engine(fold / "bundle"), seconds=0.3)
        for strip in strips:
            lis.add(bar_frame(bin_center_x(strip)), strip)
        for k in range(n_neg):
            lis.add(bar_frame(None, noise=0.3 + 0.1 * k), UNKNOWN)
        lis.save(fold / "listened_100.npz", in_view=np.arange(len(strips)))
        folds.append((fold, "src:x"))

    out = fc.fresh_check([folds], mirror=False, frames=100, choose_frames=4, seed=0, grid=cg.GRID, measure="far_mass")
    pos, neg = cg.draw_indices(len(strips), n_neg, 4, 0)
    drawn = pos + [len(strips) + j for j in neg]
    rest = [i for i in range(len(strips) + n_neg) if i not in drawn]
    assert (out["chosen_on"]["point"]["frames"], out["fresh"]["frames"], out["fresh"]["no_crossing_frames"]) == (4, 4, 1)
    averaged, _ = Listener.average(Engine(folds[0][0] / "bundle"), [f / "listened_100.npz" for f, _ in folds], "far_mass")
    threshold = out["chosen_on"]["scale"] * cg.FAR_MASS_REFERENCE
    assert out["chosen_on"]["threshold"] == pytest.approx(threshold)
    assert out["chosen_on"]["point"]["beacon_on"] == summarise(averaged.heard(threshold, drawn))["beacon_on"]
    fresh = summarise(averaged.heard(threshold, rest))
    assert out["fresh"]["beacon_on"] == pytest.approx(fresh["beacon_on"])
    assert out["fresh"]["confidently_wrong"] == pytest.approx(fresh["confidently_wrong"])
    assert out["fresh"]["silence_no_crossing"] == pytest.approx(fresh["silence_no_crossing"])

    with pytest.raises(ValueError, match="choose_gate.py .* --frames 100000"):   # no such draw saved
        fc.fresh_check([folds], mirror=False, frames=100000, choose_frames=4, seed=0, grid=cg.GRID, measure="far_mass")
    for f, _ in folds:   # a draw of 8 photos may have left photos out: its clips are not the rows' order
        (f / "listened_100.npz").rename(f / "listened_8.npz")
    with pytest.raises(ValueError, match="not every unseen photo"):
        fc.fresh_check([folds], mirror=False, frames=8, choose_frames=4, seed=0, grid=cg.GRID, measure="far_mass")
