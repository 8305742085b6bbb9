"""Training speed of 2 torchrun (DDP, gloo) processes vs 1 process, same data, same global batch.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/ddp_speed.py [--frames 160] [--size 96] [--unfreeze 2]
        [--epochs 5] [--batch-size 128] [--procs 2] [--repeats 3]

Builds a synthetic dataset (frames with a bright bar at the goal), fills the feature cache once,
then trains the same config with ``crossing-train`` (1 process, --threads 1) and with
``torchrun --nproc_per_node N crossing-train`` (--threads 1 per process), alternating, ``repeats``
times each (a shared machine's load shifts; alternating spreads it over both). Prints the median
epoch time of each (results.csv ``seconds``, epochs 2.., so start-up and cache are excluded), the
median whole-command wall time of each, the ratios 1-process / N-process (> 1: the N processes are
faster) and the load average. Both runs reach the same losses (tests/test_models_distributed.py).
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_models_train import make_tiny_dataset  # noqa: E402


def run(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    if r.returncode != 0:
        sys.exit(f"error: {' '.join(cmd[:6])} ... failed: {r.stderr.strip().splitlines()[-1:]}")
    return time.perf_counter() - t0


def epoch_seconds(out: Path) -> float:
    with open(out / "results.csv") as fh:
        secs = [float(r["seconds"]) for r in csv.DictReader(fh)]
    return float(np.median(secs[1:] if len(secs) > 1 else secs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=320)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--unfreeze", type=int, default=4)
    ap.add_argument("--epochs", type=int, default=5)
    ap.add_argument("--batch-size", type=int, default=128)
    ap.add_argument("--procs", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = make_tiny_dataset(tmp / "data", n_train=a.frames, n_val=8, size=a.size)
        common = ["--data", str(data), "--backbone", "mobilenet_v3_small", "--weights", "none",
                  "--input-size", str(a.size), "--batch-size", str(a.batch_size), "--unfreeze", str(a.unfreeze),
                  "--threads", "1", "--cache-dir", str(tmp / "cache"), "--quiet"]
        train = [sys.executable, "-m", "crossing_assist.models.cli", "train"]
        torchrun = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", str(a.procs),
                    "-m", "crossing_assist.models.cli", "train"]
        run([*train, *common, "--out", str(tmp / "warm"), "--epochs", "1"])  # fills the cache for both
        w1, wn, e1, en = [], [], [], []
        for k in range(a.repeats):
            w1.append(run([*train, *common, "--out", str(tmp / f"one{k}"), "--epochs", str(a.epochs)]))
            wn.append(run([*torchrun, *common, "--out", str(tmp / f"many{k}"), "--epochs", str(a.epochs)]))
            e1.append(epoch_seconds(tmp / f"one{k}"))
            en.append(epoch_seconds(tmp / f"many{k}"))
        print("epoch ratios per repeat:", " ".join(f"{x / y:.2f}" for x, y in zip(e1, en)))
        w1, wn, e1, en = (float(np.median(v)) for v in (w1, wn, e1, en))
    print(f"{a.frames} frames x 2 (mirror), {a.size}px, mobilenet_v3_small, last {a.unfreeze} blocks trained, "
          f"batch {a.batch_size}, {a.epochs} epochs, median of {a.repeats}, cpu cores: {os.cpu_count()}, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"1 process : epoch {e1:.2f} s, command {w1:.1f} s")
    print(f"{a.procs} processes: epoch {en:.2f} s, command {wn:.1f} s")
    print(f"speed-up (1 / {a.procs} processes): epoch {e1 / en:.2f}x, command {w1 / wn:.2f}x")


if __name__ == "__main__":
    main()
