"""compute_metrics (numpy only) on hand-checked cases; checkpoints round-trip and fail clearly."""

import subprocess
import sys

import numpy as np
import pytest
import torch

from crossing_assist.models.metrics import compute_metrics, expected_x


def one_hot(idx, n):
    p = np.full((len(idx), n), 0.0)
    p[np.arange(len(idx)), idx] = 1.0
    return p


def test_hand_checked_numbers():
    labels = np.array([0, 6, 7, 7, 3])
    pred = np.array([0, 7, 7, 5, 0])
    m = compute_metrics(one_hot(pred, 13), labels, 13, majority=7)
    assert m["accuracy"] == pytest.approx(2 / 5)
    # errors over frames where both are known: |7-6|, |7-7|, |5-7| -> mean 1
    assert m["bin_mae"] == pytest.approx(1.0) and m["bin_mae_n"] == 3
    assert m["pred_unknown_when_known"] == 1
    assert m["majority_accuracy"] == pytest.approx(2 / 5)
    assert m["majority_bin_mae"] == pytest.approx((1 + 0 + 0 + 4) / 4)
    # classes present 0,3,6,7: recalls 1, 0, 0, 1/2
    assert m["balanced_accuracy"] == pytest.approx(1.5 / 4)
    assert np.array(m["confusion"])[7, 5] == 1 and np.array(m["confusion"]).sum() == 5
    assert m["ece"] == pytest.approx(abs(1.0 - 0.4))  # all confidences 1, accuracy 0.4


def test_top3_nll_and_far_x():
    probs = np.array([[0.0, 0.5, 0.3, 0.2], [0.1, 0.1, 0.1, 0.7]])
    labels = np.array([3, 1])
    m = compute_metrics(probs, labels, 4, far_x=np.array([0.9, np.nan]))
    assert m["top3_accuracy"] == pytest.approx(1.0)
    assert m["nll"] == pytest.approx(-(np.log(0.2) + np.log(0.1)) / 2)
    # 4 actions centred at 1/6, 1/2, 5/6: E[x] = 0.5/6 + 0.3/2 + 0.2*5/6
    assert m["far_x_error"] == pytest.approx(abs(0.5 / 6 + 0.15 + 1 / 6 - 0.9)) and m["far_x_n"] == 1
    assert expected_x(np.array([[1.0, 0, 0, 0]]), 4)[0] != expected_x(np.array([[1.0, 0, 0, 0]]), 4)[0]  # nan


def test_bad_shapes_are_rejected():
    with pytest.raises(ValueError, match="shapes"):
        compute_metrics(np.ones((3, 4)) / 4, np.zeros(2, int), 4)
    with pytest.raises(ValueError, match="labels"):
        compute_metrics(np.ones((1, 4)) / 4, np.array([4]), 4)


def test_metrics_module_needs_no_torch():
    code = "import sys, crossing_assist.models.metrics; assert 'torch' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_checkpoint_roundtrip_and_errors(tmp_path):
    from crossing_assist.models.backbones import create_backbone
    from crossing_assist.models.checkpoint import CheckpointError, load_checkpoint, load_policy, save_checkpoint
    from crossing_assist.models.heads import create_head
    from crossing_assist.models.policy import Policy, policy_config

    bb = create_backbone("mobilenet_v3_small", weights="none")
    pol = Policy(bb, create_head("spatial", bb.num_features, 8), policy_config(bb, "spatial", 8, input_size=(64, 64)))
    path = save_checkpoint(tmp_path / "w" / "a.pt", pol, {"metrics": {"accuracy": 0.5}, "epoch": 3})
    assert not list(path.parent.glob("*.tmp"))
    data = load_checkpoint(path)
    assert data["epoch"] == 3 and data["metrics"] == {"accuracy": 0.5}
    back = load_policy(path)
    x = torch.rand(1, 3, 64, 64)
    assert torch.allclose(back(x, mc=False), pol.eval()(x, mc=False))
    torch.save({"obj": object()}, tmp_path / "pickle.pt")  # a pickled object: refused
    with pytest.raises(CheckpointError, match="corrupt"):
        load_policy(tmp_path / "pickle.pt")
    with pytest.raises(CheckpointError, match="not found"):
        load_policy(tmp_path / "none.pt")
    torch.save({"format": "other"}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="not a crossing_assist"):
        load_policy(tmp_path / "other.pt")
