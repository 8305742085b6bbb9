"""Bundles side by side: how much slower per frame is each than the first.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bundle_speed.py base=DIR other=DIR [...]
        [--frame 640x480] [--rounds 15] [--block 3]

Each bundle's ``model.onnx`` (as shipped: int8 where the bundle is) on one uint8 RGB frame of
``--frame`` size (the graph fits it to the bundle's canvas, runs the backbone once and the MC
head), under the same onnxruntime options (1 thread, sequential, full optimisation), timed by
the calling thread's CPU time with rounds interleaved (``speedlib``). Prints the median ms per
call of each and the median per-round ratio to the first bundle (> 1: slower than it).
Absolute ms depend on the machine's load; quote the ratios.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from speedlib import interleaved, parse_size, ratio, session, synthetic_frames  # noqa: E402

from crossing_assist.bundle import BundleError, read_bundle  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bundles", nargs="+", help="NAME=BUNDLE_DIR (the first is the reference)")
    ap.add_argument("--frame", type=parse_size, default=(640, 480), help="frame size WxH (default 640x480)")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--block", type=int, default=3)
    a = ap.parse_args(argv)
    models = {}
    w, h = a.frame
    frame = synthetic_frames(1, h, w)[0][None]
    for item in a.bundles:
        name, sep, path = item.partition("=")
        if not sep:
            print(f"error: {item!r}: expected NAME=BUNDLE_DIR", file=sys.stderr)
            return 2
        try:
            b = read_bundle(path)
        except BundleError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        models[name] = (session(str(b.model_path)), {"frames": frame})
    timed = interleaved(models, rounds=a.rounds, block=a.block)
    first = next(iter(timed.values()))
    for name, t in timed.items():
        rel = "" if t is first else f"  x{ratio(t, first):.2f} of {first.name}"
        print(f"{name:<16} {sorted(t.ms)[len(t.ms) // 2]:7.2f} ms a frame{rel}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
