"""What levelling a rolled camera's frame costs per frame, through the runtime.

    .venv/bin/python benchmarks/level_cost.py [--bundle DIR] [--frame 640x480] [--rounds 15] [--block 5]

``Engine.predict(frame)`` against ``Engine.predict(frame, roll_deg=12)`` (the frame turned level
first, ``geometry.level``: one bilinear warp) on the same uint8 RGB frame, one onnxruntime
thread, timed by the calling thread's CPU time with rounds interleaved; also ``level`` alone.
Prints the median ms per call and the median per-round ratio (> 1: levelling costs that much
more). Absolute ms depend on the machine's load; quote the ratios.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from speedlib import parse_size, synthetic_frames  # noqa: E402

from crossing_assist.bundle import BundleError  # noqa: E402
from crossing_assist.geometry import level  # noqa: E402
from crossing_assist.runtime.demo import DEFAULT_BUNDLE  # noqa: E402
from crossing_assist.runtime.engine import Engine  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE, help="bundle folder (default: the embedded one)")
    ap.add_argument("--frame", type=parse_size, default=(640, 480), help="frame size WxH (default 640x480)")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--block", type=int, default=5)
    a = ap.parse_args(argv)
    try:
        engine = Engine(a.bundle, threads=1)
    except BundleError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    w, h = a.frame
    frame = synthetic_frames(1, h, w)[0]
    pad = engine.bundle.geometry.pad_rgb
    calls = {"predict": lambda: engine.predict(frame), "predict, levelled": lambda: engine.predict(frame, roll_deg=12.0),
             "level alone": lambda: level(frame, 12.0, pad)}
    for f in calls.values():
        f(), f()
    ms = {name: [] for name in calls}
    for _ in range(a.rounds):
        for name, f in calls.items():
            t0 = time.thread_time()
            for _ in range(a.block):
                f()
            ms[name].append(1000 * (time.thread_time() - t0) / a.block)
    med = {name: float(np.median(v)) for name, v in ms.items()}
    per_round = np.asarray(ms["predict, levelled"]) / np.asarray(ms["predict"])
    print(f"{w}x{h} frame, {a.bundle}, {a.rounds} rounds x {a.block} calls, thread CPU time (median ms per call):")
    for name, v in med.items():
        print(f"  {name:<18} {v:8.2f} ms")
    print(f"levelled / plain predict: {float(np.median(per_round)):.3f}x "
          f"(level alone is {100 * med['level alone'] / med['predict']:.1f} % of a plain predict)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
