"""The one toy bundle builder (crossing_assist.testing.toy_bundle): both presets find a bright
bar's strip through the runtime, the runtime toy's MC samples vary, a deterministic copy does not,
and the command line writes a bundle or one error line."""

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("onnx", reason="onnx builds the toy graph (pip install -e '.[train]')")

from runtime_toy import bar_frame  # noqa: E402

from crossing_assist.actions import bin_center_x  # noqa: E402
from crossing_assist.bundle import read_bundle  # noqa: E402
from crossing_assist.runtime.engine import Engine  # noqa: E402
from crossing_assist.testing.toy_bundle import APP_TOY, RUNTIME_TOY, Toy, deterministic_copy, make_toy_bundle  # noqa: E402


@pytest.mark.parametrize("toy", [RUNTIME_TOY, APP_TOY], ids=["runtime", "app"])
def test_each_preset_finds_the_bright_strip_and_is_unsure_on_a_flat_frame(tmp_path, toy):
    eng = Engine(make_toy_bundle(tmp_path / "b", toy))
    for strip in (1, 4, 9, 12):
        pred = eng.predict(bar_frame(bin_center_x(strip)))
        assert eng.space.groups[int(pred.probs.argmax())] == (strip,)
    flat = eng.predict(bar_frame(None))
    assert flat.entropy > eng.predict(bar_frame(bin_center_x(6))).entropy
    assert eng.bundle.mc.samples == toy.samples and eng.bundle.calibration.uncertainty.threshold == toy.threshold


def test_runtime_toy_samples_vary_and_the_deterministic_copy_does_not(tmp_path):
    noisy = make_toy_bundle(tmp_path / "b", RUNTIME_TOY, drop_p=0.3)
    frame = bar_frame(0.4, noise=0.5)
    eng = Engine(noisy)
    runs = [eng.predict(frame).probs for _ in range(4)]
    assert max(np.abs(r - runs[0]).max() for r in runs) > 1e-4
    det = Engine(deterministic_copy(noisy, tmp_path / "det"))
    runs = [det.predict(frame).probs for _ in range(4)]
    assert max(np.abs(r - runs[0]).max() for r in runs) == 0.0
    assert det.predict(frame).mutual_info == pytest.approx(0.0, abs=1e-6)


def test_toy_geometry_makes_a_schema3_bundle_and_bad_toys_are_refused(tmp_path):
    from crossing_assist.geometry import Geometry

    b = read_bundle(make_toy_bundle(tmp_path / "b", geometry=Geometry(fit="stretch", camera_fov_deg=(70.0, 50.0))))
    assert b.schema_version == 3 and b.camera_fov(480, 640) == 50.0
    assert read_bundle(make_toy_bundle(tmp_path / "c")).schema_version == 1
    with pytest.raises(ValueError, match="multiple of 12"):
        Toy(size=(24, 50))


def test_command_line(tmp_path):
    cmd = [sys.executable, "-m", "crossing_assist.testing.toy_bundle"]
    ok = subprocess.run(cmd + [str(tmp_path / "b"), "--app", "--mc-samples", "3"], capture_output=True, text=True)
    assert ok.returncode == 0 and read_bundle(tmp_path / "b").mc.samples == 3
    bad = subprocess.run(cmd + [str(tmp_path / "c"), "--size", "24", "50"], capture_output=True, text=True)
    assert bad.returncode == 2 and bad.stderr.startswith("error:") and bad.stderr.count("\n") == 1
