"""IIL sweep wall time: ``crossing-iil sweep`` on a local Ray of N CPUs vs ``crossing-iil run`` (sequential).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/iil_sweep_speed.py [--cpus 2] [--algo dagger upms]
        [--seeds 1 2] [--episodes 5] [--horizon 256] [--repeats 2]

Both commands run the same (algorithm, seed) runs on the crossing environment, 1 torch thread a
run, into fresh folders, alternating ``repeats`` times. Prints the median wall time of each (whole
command: the Ray one includes starting and stopping the local Ray) and the ratio sequential / Ray
(> 1: the sweep is faster). Needs Ray (``pip install -e '.[scale]'``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CLI = [sys.executable, "-m", "crossing_assist.iil.cli"]


def timed(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    if r.returncode != 0:
        sys.exit(f"error: {' '.join(cmd[2:5])} failed: {r.stderr.strip().splitlines()[-1:]}")
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cpus", type=int, default=2)
    ap.add_argument("--algo", nargs="+", default=["dagger", "upms"])
    ap.add_argument("--seeds", nargs="+", default=["1", "2"])
    ap.add_argument("--episodes", type=int, default=5)
    ap.add_argument("--horizon", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    common = ["--env", "crossing", "--algo", *a.algo, "--seeds", *a.seeds, "--episodes", str(a.episodes),
              "--horizon", str(a.horizon), "--threads", "1", "--quiet"]
    seq, ray = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.repeats):
            seq.append(timed([*CLI, "run", *common, "--out", str(Path(tmp) / f"seq{k}")]))
            ray.append(timed([*CLI, "sweep", *common, "--cpus", str(a.cpus), "--out", str(Path(tmp) / f"ray{k}")]))
    s, r = float(np.median(seq)), float(np.median(ray))
    print(f"{len(a.algo) * len(a.seeds)} runs x {a.episodes} episodes x {a.horizon} steps, crossing, "
          f"cpu cores: {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}")
    print(f"sequential run: {s:.1f} s   sweep on a local Ray of {a.cpus} CPUs: {r:.1f} s   "
          f"speed-up {s / r:.2f}x (per repeat: {' '.join(f'{x / y:.2f}' for x, y in zip(seq, ray))})")


if __name__ == "__main__":
    main()
