"""What do T=16 MC-dropout samples cost over one deterministic pass? (fp32 and int8)

For each backbone (real architecture, ``--weights none`` by default: timing only) with the
default ``spatial`` head at the backbone's own input size, this exports

* ``det``:   T=1, p=0   (one deterministic pass: the reference),
* ``mc16``:  T=16, p=0.5 (the bundle: backbone once, 16 head samples folded into the batch),
* ``naive``: T=1, p=0.5, run 16 times (what MC dropout costs without folding),
* ``batch16``: T=1, p=0.5 on a batch of 16 copies of the frame (naive, batched),

and times single-frame calls under onnxruntime's DEFAULT session options in rounds: each
round runs every graph for a block of calls (median of the block), so the graphs share the
machine's load round by round; the table shows median latencies over rounds, the median of
per-round ratios to ``det`` (calls made close together share the load of a busy machine) and
the ratio of the fastest blocks.

With ``--clock cpu`` every session gets one intra-op thread (same options for all graphs) and
the CPU time of the calling thread is measured instead of wall time: on a machine shared with
other work this measures the cost of the graph itself, which wall time cannot.

With ``--int8`` the det and mc16 graphs are also quantised (convolutions
only, as ``crossing-export --int8``) and timed in the same loop.

    python benchmarks/mc_overhead.py                      # every backbone, fp32 + int8
    python benchmarks/mc_overhead.py --backbones efficientnet_lite0 --repeats 30 --no-int8
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch

from crossing_assist.export.graph import GraphSpec, export_graph, model_bytes
from crossing_assist.models.backbones import create_backbone, list_backbones
from crossing_assist.models.heads import create_head
from crossing_assist.models.policy import Policy, policy_config

sys.path.insert(0, str(Path(__file__).resolve().parent))
from speedlib import synthetic_frames  # noqa: E402


@dataclass(frozen=True)
class BenchConfig:
    backbones: tuple[str, ...]
    repeats: int = 8
    block: int = 5
    samples: int = 16
    p: float = 0.5
    head: str = "spatial"
    weights: str = "none"
    int8: bool = True
    clock: str = "wall"          # wall: default session options; cpu: 1 intra-op thread, thread CPU time
    seed: int = 0


def bench_backbone(name: str, cfg: BenchConfig) -> dict:
    torch.manual_seed(cfg.seed)
    bb = create_backbone(name, weights=cfg.weights)
    policy = Policy(bb, create_head(cfg.head, bb.num_features, 13, p=cfg.p),
                    policy_config(bb, cfg.head, 13, p=cfg.p)).eval()
    size = bb.facts.input_size
    spec = lambda t, p: GraphSpec(size=size, mean=bb.facts.mean, std=bb.facts.std, samples=t, p=p)  # noqa: E731
    models = {"det": export_graph(policy, spec(1, 0.0)), "mc16": export_graph(policy, spec(cfg.samples, cfg.p)),
              "naive": export_graph(policy, spec(1, cfg.p))}
    frames = synthetic_frames(17, *size, seed=cfg.seed)
    if cfg.int8:
        from crossing_assist.export.quantize import quantize_convs

        for key in ("det", "mc16"):
            models[f"{key}_int8"] = quantize_convs(models[key], frames[1:])
    sizes = {k: len(model_bytes(m)) for k, m in models.items()}
    opts = ort.SessionOptions()  # default options ...
    if cfg.clock == "cpu":
        opts.intra_op_num_threads = 1  # ... except one thread: the graph runs on the calling thread
    sessions = {k: ort.InferenceSession(model_bytes(m), opts) for k, m in models.items()}
    clock = time.thread_time if cfg.clock == "cpu" else time.perf_counter
    one = frames[0][None]
    batch = np.repeat(one, cfg.samples, 0)
    calls = {k: (lambda s=s: s.run(None, {"frames": one})) for k, s in sessions.items() if k != "naive"}
    calls["naive"] = lambda s=sessions["naive"]: [s.run(None, {"frames": one}) for _ in range(cfg.samples)]
    calls["batch16"] = lambda s=sessions["naive"]: s.run(None, {"frames": batch})
    for f in calls.values():  # warm-up
        f()
    # Rounds of blocks: each graph runs ``block`` calls in a row (its first call discarded: it
    # wakes that session's thread pool), graphs alternate within a round. Interleaving single
    # calls instead lets one session's spinning pool steal the cores from the next.
    times: dict[str, list[float]] = {k: [] for k in calls}
    for _ in range(cfg.repeats):
        for k, f in calls.items():
            f()
            block = []
            for _ in range(cfg.block):
                t0 = clock()
                f()
                block.append(clock() - t0)
            times[k].append(float(np.median(block)))
    ms = {k: float(np.median(v) * 1000) for k, v in times.items()}
    best = {k: float(np.min(v) * 1000) for k, v in times.items()}
    det = np.asarray(times["det"])
    # Per-round ratios (same load on a shared machine), then their median.
    ratio = {k: float(np.median(np.asarray(v) / det)) for k, v in times.items()}
    if cfg.int8:
        ratio["mc16_int8_vs_det_int8"] = float(np.median(np.asarray(times["mc16_int8"]) / times["det_int8"]))
    return {"backbone": name, "input": list(size), "ms": ms, "min_ms": best, "ratio": ratio, "bytes": sizes}


def table(rows: list[dict], int8: bool) -> str:
    head = ("| backbone | input | det ms | T=16 ms | **T=16 / det** | (fastest blocks) | naive 16 passes / det "
            "| naive batch of 16 / det |")
    sep = "|---|---|---:|---:|---:|---:|---:|---:|"
    if int8:
        head += " int8 det ms | int8 T=16 ms | int8 T=16 / int8 det | MB fp32 / int8 |"
        sep += "---:|---:|---:|---:|"
    lines = [head, sep]
    for r in rows:
        ms, ra, mn = r["ms"], r["ratio"], r["min_ms"]
        line = (f"| {r['backbone']} | {r['input'][0]}x{r['input'][1]} | {ms['det']:.1f} | {ms['mc16']:.1f} | "
                f"**{ra['mc16']:.3f}** | {mn['mc16'] / mn['det']:.3f} | {ra['naive']:.1f} | {ra['batch16']:.1f} |")
        if int8:
            line += (f" {ms['det_int8']:.1f} | {ms['mc16_int8']:.1f} | {ra['mc16_int8_vs_det_int8']:.3f} | "
                     f"{r['bytes']['mc16'] / 1e6:.1f} / {r['bytes']['mc16_int8'] / 1e6:.1f} |")
        lines.append(line)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backbones", default=",".join(list_backbones()), help="comma-separated names")
    p.add_argument("--repeats", type=int, default=BenchConfig.repeats, help="rounds")
    p.add_argument("--block", type=int, default=BenchConfig.block, help="calls per graph per round")
    p.add_argument("--head", default=BenchConfig.head, help="head kind (spatial | columns | thesis)")
    p.add_argument("--no-int8", dest="int8", action="store_false")
    p.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                   help="wall: default session options; cpu: 1 thread, thread CPU time (busy machines)")
    p.add_argument("--json", help="also write the raw numbers here")
    a = p.parse_args(argv)
    names = tuple(n.strip() for n in a.backbones.split(",") if n.strip())
    unknown = [n for n in names if n not in list_backbones()]
    if unknown:
        print(f"error: unknown backbone(s) {unknown}; valid: {', '.join(list_backbones())}", file=sys.stderr)
        return 2
    cfg = BenchConfig(backbones=names, repeats=a.repeats, block=a.block, int8=a.int8, clock=a.clock, head=a.head)
    what = "default session options, wall time" if cfg.clock == "wall" else "1 intra-op thread, thread CPU time"
    print(f"onnxruntime {ort.__version__}, {what}, single-frame calls, {cfg.repeats} rounds of {cfg.block}",
          file=sys.stderr)
    rows = []
    for name in names:
        t0 = time.time()
        rows.append(bench_backbone(name, cfg))
        print(f"{name}: T=16 / det = {rows[-1]['ratio']['mc16']:.3f} ({time.time() - t0:.0f} s)", file=sys.stderr)
    print(f"head: {cfg.head}, T={cfg.samples}, p={cfg.p}, weights: {cfg.weights}; {what}")
    print(table(rows, cfg.int8))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
