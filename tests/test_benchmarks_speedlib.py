"""The speed benchmarks' shared helpers (``benchmarks/speedlib.py``): the profiler's per-op
breakdown and the interleaved timing loop, on the tiny residual policy's fp32 and int8
graphs. No speed is asserted (speed lives in the benchmarks only)."""

import sys
from pathlib import Path

import numpy as np

from runtime_toy import toy_bundle  # noqa: F401  (fixture)

from crossing_assist.export.graph import export_graph, model_bytes
from crossing_assist.export.quantize import quantize_convs
from tests.test_export_graph import frames
from tests.test_export_quantize import DET, residual_policy

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import speedlib  # noqa: E402


def test_profile_by_op_names_the_kernels_each_graph_runs_and_timing_interleaves():
    fp32 = export_graph(residual_policy(), DET)
    x = frames(8, seed=2)
    int8 = model_bytes(quantize_convs(fp32, list(x), mode="static", batch=4))
    feed = {"frames": x[:1]}
    ops32, total32 = speedlib.profile_by_op(model_bytes(fp32), feed, runs=3)
    ops8, total8 = speedlib.profile_by_op(int8, feed, runs=3)
    assert "QLinearConv" in ops8 and "QLinearConv" not in ops32
    assert "Resize" in ops32 and "Resize" in ops8
    assert total32 > 0 and total8 > 0
    assert abs(sum(ops8.values()) - total8) < 1e-9 and list(ops8.values()) == sorted(ops8.values(), reverse=True)
    timed = speedlib.interleaved({"fp32": (speedlib.session(model_bytes(fp32)), feed),
                                  "int8": (speedlib.session(int8), feed)}, rounds=3, block=2)
    assert [len(t.ms) for t in timed.values()] == [3, 3]
    assert np.isfinite(speedlib.ratio(timed["fp32"], timed["int8"]))


def test_int8_split_matches_the_exporter_and_keeps_unseen_frames():
    calib, unseen = speedlib.int8_split(100, 128)
    assert len(calib) == 50 and len(unseen) == 50 and not set(calib) & set(unseen)
    perm = np.random.default_rng(0).permutation(100)  # crossing-export --int8's pick
    assert list(calib) == sorted(perm[:50])


def test_bundle_speed_times_bundles_side_by_side_and_refuses_bad_arguments(toy_bundle, capsys):  # noqa: F811
    import bundle_speed

    assert bundle_speed.main([f"a={toy_bundle}", f"b={toy_bundle}", "--rounds", "2", "--block", "1", "--frame", "64x48"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in out] == ["a", "b"] and "ms a frame" in out[0] and " of a" in out[1]
    assert bundle_speed.main([str(toy_bundle)]) == 2                          # no NAME=
    assert bundle_speed.main([f"a={toy_bundle.parent / 'missing'}"]) == 2     # not a bundle
    err = capsys.readouterr().err
    assert err.count("error:") == 2 and "NAME=BUNDLE_DIR" in err


def test_level_cost_times_predict_with_and_without_levelling(toy_bundle, tmp_path, capsys):  # noqa: F811
    import level_cost

    assert level_cost.main(["--bundle", str(toy_bundle), "--rounds", "2", "--block", "1", "--frame", "64x48"]) == 0
    out = capsys.readouterr().out
    assert "predict, levelled" in out and "level alone" in out and "levelled / plain predict:" in out
    assert level_cost.main(["--bundle", str(tmp_path)]) == 1
    assert capsys.readouterr().err.startswith("error: ")
