"""crossing-eval on a tiny run: metrics.json fields and plots; clear errors."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from crossing_assist.models.config import TrainConfig
from crossing_assist.models.evaluate import EvalConfig, evaluate
from crossing_assist.models.train import train
from test_models_train import make_tiny_dataset

EVAL = [sys.executable, "-c", "import sys; from crossing_assist.models.cli import eval_main as m; sys.exit(m(sys.argv[1:]))"]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("eval")
    data = make_tiny_dataset(root / "data", n_train=8, n_val=6)
    cfg = TrainConfig(data=str(data), out=str(root / "run"), backbone="mobilenet_v3_small", weights="none",
                      head="thesis", epochs=1, batch_size=4, input_size=(64, 64), cache_dir=str(root / "cache"),
                      progress=False)
    return data, train(cfg), root


def test_eval_writes_metrics_and_plots(tiny_run):
    data, run, root = tiny_run
    entries = sorted((root / "cache").iterdir())
    out, m = evaluate(EvalConfig(data=str(data), run=str(run), examples=4, cache_dir=str(root / "cache"),
                                 progress=False))
    assert sorted((root / "cache").iterdir()) == entries   # val features reused from training
    saved = json.loads((out / "metrics.json").read_text())
    for key in ("accuracy", "bin_mae", "bin_mae_ci95", "majority_accuracy", "balanced_accuracy", "top3_accuracy",
                "far_x_error", "nll", "ece", "confusion", "reliability"):
        assert key in saved, key
    assert saved["n"] == 6 and np.array(saved["confusion"]).sum() == 6
    assert saved["majority_from"] == "train"
    for png in ("confusion_matrix.png", "reliability.png", "examples.png"):
        assert (out / png).stat().st_size > 1000


def test_eval_cli_errors_are_one_line(tiny_run, tmp_path):
    data, run, _ = tiny_run
    r = subprocess.run([*EVAL, "--data", str(data), "--run", str(tmp_path / "nope")], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.startswith("error:") and "Traceback" not in r.stderr
    r = subprocess.run([*EVAL, "--data", str(data), "--run", str(run), "--split", "test"], capture_output=True, text=True)
    assert r.returncode == 2 and "no test rows" in r.stderr
    killed = tmp_path / "killed"        # a run killed before an epoch was selected: only last.pt
    (killed / "weights").mkdir(parents=True)
    shutil.copy(run / "weights" / "last.pt", killed / "weights" / "last.pt")
    r = subprocess.run([*EVAL, "--data", str(data), "--run", str(killed)], capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert f"--run {killed / 'weights' / 'last.pt'}" in r.stderr and "resume" in r.stderr
    r = subprocess.run([*EVAL, "--data", str(data), "--run", str(killed / "weights" / "last.pt"), "--out",
                        str(tmp_path / "ev")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([*EVAL, "--data", str(data), "--bundle", str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.startswith("error:") and "Traceback" not in r.stderr


def test_eval_mirror_tta_averages_each_frame_with_its_mirror(tiny_run, tmp_path):
    data, run, root = tiny_run
    _, plain = evaluate(EvalConfig(data=str(data), run=str(run), examples=0, cache_dir=str(root / "cache"),
                                   progress=False, out=str(tmp_path / "a")))
    _, tta = evaluate(EvalConfig(data=str(data), run=str(run), examples=0, tta_mirror=True, progress=False,
                                 cache_dir=str(root / "cache"), out=str(tmp_path / "b")))
    assert tta["n"] == plain["n"] == 6 and tta["tta_mirror"] is True
    assert np.array(tta["confusion"]).sum() == 6


def test_eval_scores_a_13_action_model_in_a_coarser_space(tiny_run, tmp_path):
    from crossing_assist.actions import get_space
    from crossing_assist.models.evaluate import _eval_checkpoint, _split

    data, run, root = tiny_run
    cfg = EvalConfig(data=str(data), run=str(run), examples=2, cache_dir=str(root / "cache"), progress=False,
                     actions=4, out=str(tmp_path / "g"))
    out, m4 = evaluate(cfg)
    part = _split(cfg)
    probs13, _, _ = _eval_checkpoint(cfg, part)
    space = get_space(4)
    want = (space.bin_probs_to_action_probs(probs13).argmax(1) == space.bins_to_actions(part.labels())).mean()
    assert m4["n_actions"] == 4 and m4["grouped_from"] == 13 and list(m4["names"]) == list(space.names)
    assert m4["accuracy"] == pytest.approx(want) and np.array(m4["confusion"]).shape == (4, 4)
    assert (out / "examples.png").is_file()
    with pytest.raises(Exception, match="valid: 4, 8, 13"):
        EvalConfig(data=str(data), run=str(run), actions=5)
