"""crossing-train under torchrun (DDP, gloo): 2 CPU processes match 1 process; resume; rank 0 writes."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from crossing_assist.models.checkpoint import load_checkpoint
from crossing_assist.models.distributed import Context, rank_slice
from crossing_assist.models.train import train
from test_models_train import TRAIN, _cfg, make_tiny_dataset

TORCHRUN = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
            "-m", "crossing_assist.models.cli", "train"]
# float sums over 2 ranks + an all-reduce differ from one process's sums in the last bits only
TOL = 1e-4


def _losses(out: Path) -> list[float]:
    with open(out / "results.csv") as fh:
        return [float(r["train_loss"]) for r in csv.DictReader(fh)]


def test_rank_slice_splits_every_batch_and_pads_an_empty_rank():
    batch = np.array([7, 3, 5, 1, 9])
    parts = [rank_slice(batch, Context(r, 2)) for r in range(2)]
    assert sorted(np.concatenate([p for p, _ in parts]).tolist()) == sorted(batch.tolist())
    assert all(k.tolist() == [1.0] * len(p) for p, k in parts)
    idx, keep = rank_slice(np.array([4]), Context(1, 2))  # last batch of one sample: rank 1 has none
    assert idx.tolist() == [4] and keep.tolist() == [0.0]


def test_two_gloo_processes_match_one_process_and_resume(tmp_path):
    """Same global batch (5, so the last batch of 16 samples leaves rank 1 empty), dropout off (its
    masks depend on the per-rank batch), the loss terms that do not split per sample (aux far-x
    mean) and the goal-position targets (--soft-x) included, one block unfrozen: per-epoch losses
    and final weights agree within TOL."""
    data = make_tiny_dataset(tmp_path / "data")
    opts = dict(epochs=2, batch_size=5, p=0.0, aux_x=1.0, smoothing=0.1, soft_x=0.4, balance="weights", unfreeze=1,
                threads=1)
    one = train(_cfg(data, tmp_path / "one", **opts))
    out, cache = tmp_path / "two", tmp_path / "cache2"
    args = ["--data", str(data), "--out", str(out), "--backbone", "mobilenet_v3_small", "--weights", "none",
            "--input-size", "64", "--batch-size", "5", "--dropout", "0", "--aux-x", "1", "--smoothing", "0.1",
            "--soft-x", "0.4", "--balance", "weights", "--unfreeze", "1", "--threads", "1", "--cache-dir", str(cache),
            "--quiet"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONFAULTHANDLER": "1"}   # a worker that dies says where
    r = subprocess.run([*TORCHRUN, *args, "--epochs", "1"], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.count("trained 1 epochs") == 1          # rank 0 alone reports
    assert sorted(p.name for p in out.iterdir()) == ["args.yaml", "results.csv", "results.png", "weights"]
    assert len(list(cache.iterdir())) == 2                  # train + val entries, built once, no leftovers
    r = subprocess.run([*TORCHRUN, *args, "--epochs", "2", "--resume"], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert np.allclose(_losses(out), _losses(one), atol=TOL, rtol=0), (_losses(out), _losses(one))
    a = load_checkpoint(one / "weights" / "last.pt")["state_dict"]
    b = load_checkpoint(out / "weights" / "last.pt")["state_dict"]
    assert load_checkpoint(out / "weights" / "last.pt")["epoch"] == 2
    assert max(float((a[k].float() - b[k].float()).abs().max()) for k in a) < TOL


def test_cv_under_torchrun_is_refused_with_one_line(tmp_path):
    data = make_tiny_dataset(tmp_path / "data")
    r = subprocess.run([*TRAIN, "--data", str(data), "--out", str(tmp_path / "cv"), "--cv", "source", "--quiet"],
                       capture_output=True, text=True, env={**os.environ, "WORLD_SIZE": "2"})
    assert r.returncode != 0 and r.stderr.startswith("error:") and "--cv" in r.stderr
    assert r.stderr.strip().count("\n") == 0 and not (tmp_path / "cv").exists()


def test_leave_flushes_the_output_and_exits_with_the_code_given():
    """A torchrun worker's last words survive its hard exit (stdout to a pipe is block-buffered)."""
    code = ("import sys; from crossing_assist.models import distributed; print('trained 2 epochs'); "
            "print('a warning', file=sys.stderr); distributed.leave(3)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"})
    assert (r.returncode, r.stdout, r.stderr) == (3, "trained 2 epochs\n", "a warning\n")
