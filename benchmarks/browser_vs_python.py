"""The phone app's model latency in headless Chromium against Python's onnxruntime, side by side.

Each round runs ``android_demo/tools/bench_browser.mjs`` (a fresh Chromium profile: the app's
first load, then ``--runs`` timed calls of the app's Model.run) and, right after it, the same
number of :meth:`Engine.predict` calls in Python with one thread on the same synthetic frame
size, so both share the machine's load round by round. Prints a JSON line per round and a
summary: medians over rounds, the median per-round ratio browser / Python, the first-load
bytes and the offline cache bytes.

    node android_demo/tools/build.mjs                # www/ with the default bundle
    python benchmarks/browser_vs_python.py --rounds 3 --runs 20 [--threads 1]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from crossing_assist.runtime.engine import Engine

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "android_demo"


def python_ms(engine: Engine, h: int, w: int, runs: int) -> float:
    rgb = np.random.default_rng(0).integers(0, 256, (h, w, 3), dtype=np.uint8)
    for _ in range(3):
        engine.predict(rgb)
    ms = []
    for _ in range(runs):
        t0 = time.perf_counter()
        engine.predict(rgb)
        ms.append(1000 * (time.perf_counter() - t0))
    return float(np.median(ms))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bundle", type=Path, default=REPO / "crossing_assist" / "assets" / "default_bundle")
    ap.add_argument("--www", type=Path, default=DEMO / "www")
    ap.add_argument("--size", default="480x640")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--threads", type=int, default=0, help="browser WASM threads (0 = the app's choice)")
    a = ap.parse_args(argv)
    node = shutil.which("node")
    if node is None or not (a.www / "precache.json").is_file():
        print("error: needs node and a built android_demo/www (node android_demo/tools/build.mjs)", file=sys.stderr)
        return 2
    h, w = (int(v) for v in a.size.split("x"))
    engine = Engine(a.bundle, threads=1)
    rows = []
    for _ in range(a.rounds):
        out = subprocess.run([node, str(DEMO / "tools" / "bench_browser.mjs"), "--www", str(a.www), "--size", a.size,
                              "--runs", str(a.runs), "--threads", str(a.threads)], capture_output=True, text=True,
                             timeout=900)
        if out.returncode != 0:
            print(out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "error: bench_browser failed",
                  file=sys.stderr)
            return 1
        row = json.loads(out.stdout.strip().splitlines()[-1])
        row["python_ms"] = python_ms(engine, h, w, a.runs)
        row["ratio"] = row["median_ms"] / row["python_ms"]
        rows.append(row)
        print(json.dumps(row))
    print(json.dumps({"summary": True, "bundle": rows[0]["bundle"], "backend": rows[0]["backend"],
                      "threads": rows[0]["threads"], "size": [h, w],
                      "browser_ms": statistics.median(r["median_ms"] for r in rows),
                      "python_ms": statistics.median(r["python_ms"] for r in rows),
                      "ratio": statistics.median(r["ratio"] for r in rows),
                      "first_load_bytes": rows[0]["first_load_bytes"], "cache_bytes": rows[0]["cache_bytes"]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
