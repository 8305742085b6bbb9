"""crossing-export refuses a calibration set too small to calibrate (fewer than --min-calib frames
with a crossing, default 50) in one line, before any work; --min-calib N accepts fewer, and a fit
that ended on a clip (temperature at 20, a gate threshold at the measure's maximum) is named in a
``warning:`` line. The audit's case: 8 frames the model gets all wrong gave temperature 20 and a
gate threshold of ln 13, written as if fine."""

import subprocess
import sys

import numpy as np
import pytest
import torch
from export_toy import tiny_policy
from runtime_toy import bar_dataset, make_toy_bundle

from crossing_assist.bundle import read_bundle
from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import Row, write_manifest
from crossing_assist.export import calibrate as cal
from crossing_assist.export.exporter import (
    MIN_CALIB_CROSSINGS,
    ExportConfig,
    ExportError,
    _spec,
    check_calib_size,
    export_bundle,
)
from crossing_assist.export.graph import BundleGraph
from crossing_assist.models.checkpoint import save_checkpoint

N_ACTIONS = 13   # one action a strip: action k is bin k


def _refusal(data, n: int, of: int, need: int = MIN_CALIB_CROSSINGS) -> str:
    return (f"Invalid --calib-data {data}: split 'val' has {n} frames with a crossing (of {of}); calibrating a gate "
            f"needs at least {need}, fewer fit it to noise: label more frames or pass --min-calib N to accept fewer")


@pytest.fixture(scope="module")
def wrong8(tmp_path_factory):
    """A tiny run and 8 frames all labelled with the strip the model likes least (never its argmax):
    the model is confidently wrong on every one, as in the audit."""
    root = tmp_path_factory.mktemp("calib_size")
    policy = tiny_policy(N_ACTIONS)
    save_checkpoint(root / "run" / "weights" / "best.pt", policy, {"metrics": {}})
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (40, 48, 3), dtype=np.uint8) for _ in range(8)]
    policy.eval()
    with torch.no_grad():
        probs = BundleGraph(policy, _spec(policy.config, 1, 0.0))(torch.from_numpy(np.stack(images)))[0].numpy()
    liked = np.log(probs[:, 1:]).mean(0)
    liked[probs.argmax(1)[probs.argmax(1) > 0] - 1] = np.inf
    label = int(np.argmin(liked)) + 1
    rows = []
    for i, im in enumerate(images):
        save_rgb(root / "data" / f"f{i}.png", im)
        rows.append(Row(image=f"f{i}.png", label=label, far_x=(label - 0.5) / 12, source=f"vid:{i % 3}", split="val"))
    write_manifest(root / "data", rows)
    return root


def _export(*args):
    return subprocess.run([sys.executable, "-m", "crossing_assist.export", *map(str, args), "--quiet"],
                          capture_output=True, text=True, timeout=300)


def test_check_calib_size_counts_the_frames_with_a_crossing():
    assert MIN_CALIB_CROSSINGS == 50 and ExportConfig(run="r", out="o").min_calib == MIN_CALIB_CROSSINGS
    actions = np.array([0] * 11 + [3] * 49)   # 60 frames, 49 with a crossing: the unknown ones do not count
    with pytest.raises(ExportError) as err:
        check_calib_size("d", "val", actions)
    assert str(err.value) == _refusal("d", 49, 60)
    check_calib_size("d", "val", np.append(actions, 5))        # 50: enough
    check_calib_size("d", "val", actions, min_calib=49)        # the override
    with pytest.raises(ExportError, match="needs at least 60"):
        check_calib_size("d", "val", np.append(actions, 5), min_calib=60)
    with pytest.raises(ExportError, match="^Invalid --min-calib 0; valid: >= 1$"):
        ExportConfig(run="r", out="o", min_calib=0)


def test_export_refuses_a_tiny_calibration_set_before_any_work(wrong8, tmp_path):
    logged = []
    with pytest.raises(ExportError) as err:
        export_bundle(ExportConfig(run=str(wrong8 / "run"), out=str(tmp_path / "b"), calib_data=str(wrong8 / "data"),
                                   samples=1, p=0.0, parity_frames=2, progress=False), log=logged.append)
    assert str(err.value) == _refusal(wrong8 / "data", 8, 8)
    assert logged == [] and not (tmp_path / "b").exists()   # refused before the MC logits, nothing written


def test_cli_refuses_a_tiny_calibration_set_in_one_line_and_min_calib_accepts_it_with_warnings(wrong8, tmp_path):
    out = tmp_path / "bundle"
    common = ("--run", wrong8 / "run", "--out", out, "--calib-data", wrong8 / "data", "--samples", "1", "--p", "0",
              "--parity-frames", "2", "--threads", "1")
    r = _export(*common)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.splitlines() == ["error: " + _refusal(wrong8 / "data", 8, 8)]
    assert not out.exists()

    r = _export(*common, "--min-calib", "8")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"bundle written: {out} (")
    b = read_bundle(out)
    assert b.calibration.temperature == pytest.approx(cal.TEMP_RANGE[1], rel=1e-3)   # the audit's clip
    warnings = [line for line in r.stderr.splitlines() if line.startswith("warning: ")]
    assert warnings[0].startswith("warning: temperature 20 is at its upper clip 20: the fit flattened the model's "
                                  "probabilities as far as it may, the model is confidently wrong on --calib-data")
    assert warnings[1].startswith("warning: the gate threshold fit ended on its clip, the 5 % quantile of entropy "
                                  "on --calib-data") and "the model is wrong on every one of them" in warnings[1]
    t = b.calibration.uncertainty.threshold
    assert t >= 0.99 * np.log(N_ACTIONS)                                             # ln 13: the gate passes all
    assert warnings[2] == (f"warning: the gate threshold {t:.4g} is within 1 % of the largest entropy possible with "
                           f"13 actions ({np.log(13):.4g}): the gate passes nearly every frame, however unsure the "
                           "model is")
    assert len(warnings) == 3


def test_ensemble_refuses_a_tiny_calibration_set_unless_min_calib_says(tmp_path):
    from crossing_assist.export.ensemble import EnsembleConfig, ensemble_bundle

    a, b = (make_toy_bundle(tmp_path / n, drop_p=0.0, noise=0.0, samples=2, gain=g) for n, g in (("a", 12.0), ("b", 3.0)))
    data = bar_dataset(tmp_path / "data", n=6)
    cmd = [sys.executable, "-m", "crossing_assist.export", "ensemble", str(a), str(b), "--out", str(tmp_path / "ens"),
           "--calib-data", str(data), "--quiet"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    errors = [line for line in r.stderr.splitlines() if line.startswith("error")]
    assert r.returncode == 2 and errors == ["error: " + _refusal(data, 6, 6)] == r.stderr.splitlines()[-1:]
    assert not (tmp_path / "ens").exists()
    with pytest.raises(ExportError, match="has 6 frames with a crossing"):   # the library call: the same default
        ensemble_bundle(EnsembleConfig(members=(str(a), str(b)), out=str(tmp_path / "ens"), calib_data=str(data),
                                       progress=False), log=lambda m: None)
    r = subprocess.run(cmd + ["--min-calib", "0"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.splitlines() == ["error: Invalid --min-calib 0; valid: >= 1"]
    r = subprocess.run(cmd + ["--min-calib", "6"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert read_bundle(tmp_path / "ens").mc.members == 2


def test_temperature_warning_names_either_clip():
    lo, hi = cal.TEMP_RANGE
    assert cal.temperature_warning(hi).startswith("temperature 20 is at its upper clip 20:")
    assert cal.temperature_warning(lo).startswith("temperature 0.05 is at its lower clip 0.05:")
    assert cal.temperature_warning(1.3) is None and cal.temperature_warning(19.0) is None
    rng = np.random.default_rng(0)
    logits = rng.normal(0, 1, (1, 40, 4))
    logits[0, :, 1] += 6.0                                 # sure of action 1 ...
    assert cal.temperature_warning(cal.fit_temperature(logits, np.full(40, 2))) is not None   # ... always wrong


def test_gate_warnings_only_for_a_fit_that_is_not_a_gate():
    rng = np.random.default_rng(0)
    u = rng.uniform(0, 2, 2000)
    correct = rng.random(2000) < 1 / (1 + np.exp(8 * (u - 1.2)))   # right below 1.2, wrong above
    fit = cal.fit_gate(u, correct)
    assert fit.clip is None and fit.signal and fit.threshold == cal.uncertainty_threshold(u, correct)
    assert cal.gate_warnings(u, fit, fit.threshold, "entropy", 13) == []
    # no signal, mostly right: the 95 % clip decides
    fit = cal.fit_gate(u, rng.random(2000) < 0.9)
    assert fit.clip == "95 %" and not fit.signal
    [w] = cal.gate_warnings(u, fit, fit.threshold, "entropy", 13)
    assert w.startswith("the gate threshold fit ended on its clip, the 95 % quantile of entropy on --calib-data")
    assert "entropy does not tell the frames the model gets right from those it gets wrong" in w and "passes 95%" in w
    # a scale that lifts the threshold above every frame: the gate passes all of them
    fit = cal.fit_gate(u, correct)
    [w] = cal.gate_warnings(u, fit, 2.1, "entropy", 13)
    assert w == f"the gate threshold 2.1 is above the entropy of every frame of --calib-data (largest {u.max():.4g}): " \
                "the gate passes all 2000 of them"
    [w] = cal.gate_warnings(u / 2, cal.fit_gate(u / 2, correct), 0.995, "far_mass", 13)
    assert w.startswith("the gate threshold 0.995 is within 1 % of the largest far_mass possible with 13 actions (1)")
