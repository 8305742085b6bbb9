"""crossing-train: run folder, caching, resume after a kill, corrupt checkpoints, CLI errors."""

import csv
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import Row, write_manifest
from crossing_assist.models.checkpoint import CheckpointError, load_checkpoint, load_policy
from crossing_assist.models.config import TrainConfig
from crossing_assist.models.train import train

TRAIN = [sys.executable, "-c", "import sys; from crossing_assist.models.cli import train_main as m; sys.exit(m(sys.argv[1:]))"]


def make_tiny_dataset(root: Path, n_train: int = 8, n_val: int = 4, size: int = 64, seed: int = 0) -> Path:
    """Frames with a bright vertical bar at the goal position (label = its strip); one unknown."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n_train + n_val):
        split = "train" if i < n_train else "val"
        img = rng.integers(0, 60, (size, size, 3), dtype=np.uint8)
        if i % 5 == 4:
            far_x, label = None, 0
        else:
            far_x = float(rng.uniform(0.05, 0.95))
            label = min(12, int(far_x * 12) + 1)
            c = int(far_x * size)
            img[:, max(0, c - 2):c + 2] = 255
        save_rgb(root / "images" / f"f{i:03d}.png", img)
        rows.append(Row(f"images/f{i:03d}.png", label, far_x, f"src:{i % 3}", split))
    write_manifest(root, rows)
    return root


@pytest.fixture()
def tiny(tmp_path):
    return make_tiny_dataset(tmp_path / "data")


def _cfg(tiny: Path, out: Path, **kw) -> TrainConfig:
    base = dict(data=str(tiny), out=str(out), backbone="mobilenet_v3_small", weights="none", epochs=2,
                batch_size=4, input_size=(64, 64), cache_dir=str(out.parent / "cache"), progress=False)
    base.update(kw)
    return TrainConfig(**base)


def test_run_folder_has_everything_and_best_loads(tiny, tmp_path):
    extra = make_tiny_dataset(tmp_path / "extra", n_train=3, n_val=1, seed=1)
    out = train(_cfg(tiny, tmp_path / "run", yaw=(10.0,), smoothing=0.1, balance="weights", aux_x=1.0,
                     extra_data=(str(extra),)))
    for name in ("args.yaml", "results.csv", "results.png", "weights/best.pt", "weights/last.pt"):
        assert (out / name).is_file(), name
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["epoch"]) for r in rows] == [1, 2]
    assert all(float(r["val_accuracy"]) >= 0 for r in rows)
    policy = load_policy(out / "weights" / "best.pt")
    assert policy.config.input_size == (64, 64) and policy.n_actions == 13
    # mirrored + yaw +-10 -> 6 variants of the 8 train frames
    assert policy.config.counts["train_samples"] == (8 + 3) * 6 and policy.config.counts["extra_train"] == 3
    logits = policy(torch.zeros(2, 3, 64, 64), samples=3, mc=False)
    assert logits.shape == (3, 2, 13)


def test_existing_run_refused_without_resume(tiny, tmp_path):
    train(_cfg(tiny, tmp_path / "run", epochs=1))
    from crossing_assist.models.config import ConfigError
    with pytest.raises(ConfigError, match="--resume"):
        train(_cfg(tiny, tmp_path / "run", epochs=1))


def test_a_second_run_on_a_folder_being_written_is_refused(tiny, tmp_path):
    """Two crossing-train on one --out both exited 0, leaving args.yaml and best.pt of one run with
    results.csv and last.pt of the other. While one holds the folder, the other is refused; once it
    ends, the folder is free (the lock is not left behind)."""
    from crossing_assist.models.cache import entry_lock
    from crossing_assist.models.config import ConfigError
    out = tmp_path / "run"
    with entry_lock(out, ".run", wait=False) as held:      # the first run, still training
        assert held
        with pytest.raises(ConfigError, match="another crossing-train is writing"):
            train(_cfg(tiny, out, epochs=1))
        assert not (out / "weights").exists() and not (out / "args.yaml").exists()
    train(_cfg(tiny, out, epochs=1))
    assert (out / "weights" / "best.pt").is_file() and not (out / ".run.lock").exists()


def test_corrupt_checkpoint_gives_clear_error(tiny, tmp_path):
    out = train(_cfg(tiny, tmp_path / "run", epochs=1))
    best = out / "weights" / "best.pt"
    data = best.read_bytes()
    best.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt"):
        load_policy(best)
    (out / "weights" / "last.pt").write_bytes(b"garbage")
    r = subprocess.run([*TRAIN, "--data", str(tiny),
                        "--out", str(out), "--resume", "--quiet"], capture_output=True, text=True)
    assert r.returncode != 0
    assert r.stderr.startswith("error:") and "corrupt" in r.stderr and "Traceback" not in r.stderr


def test_cli_bad_input_is_one_line(tiny, tmp_path):
    r = subprocess.run([*TRAIN, "--data", str(tiny),
                        "--out", str(tmp_path / "r"), "--backbone", "vgg"], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "valid:" in r.stderr


@pytest.mark.slow
def test_resume_after_kill_mid_epoch(tmp_path):
    tiny = make_tiny_dataset(tmp_path / "data", n_train=40, n_val=8)
    out = tmp_path / "run"
    args = [*TRAIN, "--data", str(tiny), "--out", str(out),
            "--backbone", "mobilenet_v3_small", "--weights", "none", "--input-size", "64", "--epochs", "8",
            "--batch-size", "2", "--unfreeze", "3", "--threads", "1", "--cache-dir", str(tmp_path / "cache"), "--quiet"]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    last = out / "weights" / "last.pt"
    deadline = time.time() + 600
    while time.time() < deadline and not (last.is_file() and load_checkpoint(last)["epoch"] >= 2):
        time.sleep(0.2)
    assert last.is_file() and load_checkpoint(last)["epoch"] >= 2, "training too slow to reach epoch 2"
    time.sleep(0.2)  # inside the next epoch (40 steps through the 3 unfrozen blocks)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    killed_at = load_checkpoint(last)["epoch"]
    assert 2 <= killed_at < 8
    r = subprocess.run(args + ["--resume"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert load_checkpoint(last)["epoch"] == 8
    with open(out / "results.csv") as fh:
        assert [int(x["epoch"]) for x in csv.DictReader(fh)] == list(range(1, 9))
    best = load_policy(out / "weights" / "best.pt")
    assert 1 <= load_checkpoint(out / "weights" / "best.pt")["epoch"] <= 8
    assert best(torch.zeros(1, 3, 64, 64), mc=False).shape == (1, 1, 13)


def test_cache_is_reused_and_deeper_entries_derive_from_shallower(tiny, tmp_path):
    from crossing_assist.data_tools.manifest import read_manifest
    from crossing_assist.models.backbones import create_backbone
    from crossing_assist.models.cache import compute_features
    from crossing_assist.models.data import make_variants

    ds = read_manifest(tiny).split("train")
    bb = create_backbone("mobilenet_v3_small", weights="none").eval()
    v = make_variants(True)
    a = compute_features(bb, 6, ds, (64, 64), v, 90.0, tmp_path / "c", progress=False)
    assert a.feats.shape[0] == len(ds) * 2 and (a.labels[1::2] == [13 - b if b else 0 for b in a.labels[::2]]).all()
    assert compute_features(bb, 6, ds, (64, 64), v, 90.0, tmp_path / "c", progress=False).path == a.path
    deep = compute_features(bb, 13, ds, (64, 64), v, 90.0, tmp_path / "c", progress=False)
    with torch.no_grad():
        direct = bb.forward_from(torch.from_numpy(np.array(a.feats)).float(), 6).numpy()
    assert np.allclose(deep.feats, direct, atol=2e-2, rtol=1e-2)
    # a different variant list or input size is a different entry
    other = compute_features(bb, 6, ds, (64, 64), make_variants(False), 90.0, tmp_path / "c", progress=False)
    assert other.path != a.path and other.feats.shape[0] == len(ds)


def test_holdout_sources_are_masked_from_one_cache(tiny, tmp_path):
    out = train(_cfg(tiny, tmp_path / "run", epochs=1, holdout=("src:0",), select_on="holdout"))
    counts = load_policy(out / "weights" / "best.pt").config.counts
    # train rows 0..7, sources i % 3: src:0 holds rows 0, 3, 6 -> 5 rows x 2 (mirror) train, 3 held-out frames
    assert counts["train_samples"] == 10 and counts["holdout_frames"] == 3
    assert len(list((tmp_path / "cache").iterdir())) == 2   # train split + val, no extra entry
    from crossing_assist.models.config import ConfigError
    with pytest.raises(ConfigError, match="not among train sources"):
        train(_cfg(tiny, tmp_path / "run2", holdout=("ptl:nobody",), select_on="holdout"))


def test_unfreeze_trains_the_last_blocks_and_only_them(tiny, tmp_path):
    """Same seed, same data: with --unfreeze 2 the last two backbone blocks move away from the
    frozen run's, every earlier block stays bit-identical."""
    frozen = load_policy(train(_cfg(tiny, tmp_path / "frozen", epochs=1)) / "weights" / "last.pt")
    tuned = load_policy(train(_cfg(tiny, tmp_path / "tuned", epochs=1, unfreeze=2)) / "weights" / "last.pt")
    blocks = list(zip(frozen.backbone.blocks, tuned.backbone.blocks))
    same = [all(torch.equal(a, b) for a, b in zip(fa.state_dict().values(), ta.state_dict().values()))
            for fa, ta in blocks]
    assert same[:-2] == [True] * (len(blocks) - 2) and same[-2:] == [False, False]
    assert tuned.config.frozen_blocks == len(blocks) - 2


def test_cosine_schedule_falls_to_zero_and_constant_stays(tiny, tmp_path):
    """--lr-schedule cosine: the step size the optimizer last used (saved in last.pt) is near 0 at
    the end of the run; constant keeps --lr. The curve is a function of the position alone, so a
    resumed run continues on it."""
    from crossing_assist.models.train import _set_lr

    def last_lr(run):
        return load_checkpoint(run / "weights" / "last.pt")["optimizer"]["param_groups"][0]["lr"]

    cosine = train(_cfg(tiny, tmp_path / "cos", lr=1e-3, lr_schedule="cosine", epochs=2))
    constant = train(_cfg(tiny, tmp_path / "const", lr=1e-3, epochs=2))
    assert last_lr(constant) == pytest.approx(1e-3)
    assert 0 < last_lr(cosine) < 0.2e-3   # the last step of epoch 2 of 2, whatever the steps an epoch
    opt = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=1.0)
    cfg = _cfg(tiny, tmp_path / "x", lr=1.0, lr_schedule="cosine", epochs=4)
    curve = []
    for epoch in range(1, 5):
        for step in range(10):
            _set_lr(opt, cfg, epoch, step, 10)
            curve.append(opt.param_groups[0]["lr"])
    assert curve[0] == 1.0 and curve[20] == pytest.approx(0.5) and all(np.diff(curve) < 0) and curve[-1] < 0.01
    with pytest.raises(Exception, match="lr_schedule"):
        _cfg(tiny, tmp_path / "y", lr_schedule="step")


def test_plot_training_writes_results_png_from_results_csv(tmp_path):
    """models.plots.plot_training (what train() calls at the end); blank cells (no val set) are gaps."""
    from crossing_assist.models.plots import plot_training
    from crossing_assist.models.train import RESULT_FIELDS

    rows = [{"epoch": e, "train_loss": 1.0 / e, "sel_accuracy": 0.1 * e, "sel_bin_mae": "", "sel_nll": "",
             "val_accuracy": "", "val_bin_mae": "", "val_nll": "", "seconds": 0.1} for e in (1, 2, 3)]
    with open(tmp_path / "results.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=RESULT_FIELDS)
        w.writeheader()
        w.writerows(rows)
    path = plot_training(tmp_path)
    assert path == tmp_path / "results.png" and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.csv", "results.png"]   # no temp file left


def test_feature_stride_16_needs_its_skip_block_unfrozen(tiny, tmp_path):
    from crossing_assist.models.config import ConfigError

    with pytest.raises(ConfigError, match="unfreeze >= 7"):
        train(_cfg(tiny, tmp_path / "run", backbone="efficientnet_lite0", feature_stride=16, unfreeze=2, epochs=1))
    with pytest.raises(ConfigError, match="feature_stride 8"):
        _cfg(tiny, tmp_path / "run", feature_stride=8)


def test_soft_x_targets_lean_toward_the_goal_across_a_strip_edge():
    from crossing_assist.models.train import _targets

    nan = float("nan")
    actions = torch.tensor([0, 6, 6, 1, 12, 4])
    far_x = torch.tensor([nan, 5.5 / 12, 5.95 / 12, 0.0, 1.0, nan])
    t = _targets(actions, 13, 0.2, far_x, soft_x=0.4)
    assert torch.allclose(t.sum(1), torch.ones(6))
    assert t[0, 0] == 1                                           # unknown stays unknown
    assert abs(float(t[1, 6]) - 0.789) < 1e-3 and torch.isclose(t[1, 5], t[1, 7])   # strip middle: symmetric
    assert float(t[2, 7]) > 0.4 > float(t[2, 5]) * 20            # near its right edge: leans right
    assert float(t[3, 1]) > 0.99 and float(t[4, 12]) > 0.99       # edge strips reach past the frame
    assert torch.allclose(t[5], _targets(actions[5:], 13, 0.2)[0])   # no position: smoothing to both neighbours
    eight = _targets(torch.tensor([2]), 8, 0.0, torch.tensor([2.0 / 12]), soft_x=0.4)  # on the edge inside action {2,3}
    assert float(eight[0, 2]) > 0.98
    assert torch.equal(_targets(actions, 13, 0.2, far_x, soft_x=0.0), _targets(actions, 13, 0.2))


def test_soft_x_changes_what_is_learned_and_is_checked(tiny, tmp_path):
    from crossing_assist.models.config import ConfigError

    a = train(_cfg(tiny, tmp_path / "a", epochs=1, p=0.0))
    b = train(_cfg(tiny, tmp_path / "b", epochs=1, p=0.0, soft_x=0.4))
    la, lb = (load_checkpoint(r / "weights" / "last.pt")["state_dict"] for r in (a, b))
    assert any(not torch.equal(la[k], lb[k]) for k in la)
    assert load_checkpoint(b / "weights" / "last.pt")["train_config"]["soft_x"] == 0.4   # --resume keeps it
    with pytest.raises(ConfigError, match="soft_x 5"):
        _cfg(tiny, tmp_path / "c", soft_x=5)


def test_class_weights_inverse_frequency_and_its_milder_square_root(tiny, tmp_path):
    from crossing_assist.models.config import ConfigError
    from crossing_assist.models.train import _class_weights

    actions = np.array([1] * 9 + [2] * 4 + [3] * 1)      # strips 1, 2, 3; the others absent
    full, sqrt = _class_weights(actions, 13).numpy(), _class_weights(actions, 13, 0.5).numpy()
    for w in (full, sqrt):
        assert w[0] == 0 and w[4:].sum() == 0 and w[1:4].mean() == pytest.approx(1.0)   # mean 1 over present
    assert full[3] / full[1] == pytest.approx(9.0) and sqrt[3] / sqrt[1] == pytest.approx(3.0)
    assert sqrt[2] / sqrt[1] == pytest.approx(1.5)
    # --balance sqrt trains with those weights: another model than --balance weights, from one seed
    a = train(_cfg(tiny, tmp_path / "a", epochs=1, p=0.0, balance="weights"))
    b = train(_cfg(tiny, tmp_path / "b", epochs=1, p=0.0, balance="sqrt"))
    la, lb = (load_checkpoint(r / "weights" / "last.pt")["state_dict"] for r in (a, b))
    assert any(not torch.equal(la[k], lb[k]) for k in la)
    with pytest.raises(ConfigError, match="balance 'cube'"):
        _cfg(tiny, tmp_path / "c", balance="cube")


def test_frames_of_another_camera_than_fov_are_named(tmp_path):
    """Rows flagged ``fov=40.8`` (crossing-data frames --fov) trained at --fov 67: one line saying
    how many and which camera; none when they agree; a bad flag is a ConfigError."""
    from crossing_assist.data_tools.manifest import Dataset, Row
    from crossing_assist.models.config import ConfigError
    from crossing_assist.models.train import fov_mismatch

    rows = [Row(f"f{i}.jpg", 6, None, "vid:a", "train", {}, ("fov=40.8",) if i < 3 else ()) for i in range(5)]
    ds = Dataset(tmp_path, rows)
    msg = fov_mismatch(ds, 67.0)
    assert msg and msg.startswith("3 frames") and "3 at 40.8 deg" in msg and "--fov 67" in msg
    assert fov_mismatch(ds, 40.5) is None
    with pytest.raises(ConfigError, match="fov=abc"):
        fov_mismatch(Dataset(tmp_path, [Row("f.jpg", 6, None, "vid:a", "train", {}, ("fov=abc",))]), 67.0)
