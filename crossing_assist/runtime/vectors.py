"""Shared decision test vectors: the phone app must reproduce these decisions exactly.

    python -m crossing_assist.runtime.vectors --out android_demo/test_vectors.json

Each scenario gives the full :class:`DecisionConfig`, then one entry per step with the inputs
(``t`` seconds, ``yaw_rate_dps``, and ``obs``: null for a tick without a frame, else the
graph's raw outputs ``ok``, ``probs``, ``entropy``, ``mutual_info``, ``variance`` and the derived
``uncertainty``, the bundle's measure) and the expected :class:`Decision` (every field, the belief
included). Inputs are generated from a seeded generator, so the file is reproducible. Floats
are written at full double precision; a port should agree to ~1e-9 (``tolerance``), and on
every discrete field (gate, reason, stop, learner_action) exactly. Plus pure-function vectors
for the beacon (pan gains, ITD, pulse loop length, heading -> pan).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crossing_assist.actions import get_space, heading_to_pan
from crossing_assist.fileio import atomic_write_text
from crossing_assist.runtime.beacon import BeaconConfig, itd_seconds, pan_gains
from crossing_assist.runtime.decide import Decider, DecisionConfig, Observation
from crossing_assist.runtime.engine import measure_value

FPS = 30.0
VERSION = 1


def _probs_for(space_n: int, action: int, conf: float) -> np.ndarray:
    p = np.full(space_n, (1.0 - conf) / (space_n - 1))
    p[action] = conf
    return p


def _entropy(p: np.ndarray) -> float:
    return float(-(p * np.log(p)).sum())


@dataclass(frozen=True)
class RawOutputs:
    """A frame's graph outputs as the bundle gives them (``ok=False``: inference failed)."""

    probs: np.ndarray | None
    entropy: float = math.inf
    mutual_info: float = math.inf
    variance: np.ndarray | None = None
    ok: bool = True

    def observation(self, measure: str) -> Observation:
        """What the decision logic sees: ``probs`` and the bundle's measure (engine rule)."""
        if not self.ok:
            return Observation(None, math.inf, ok=False)
        return Observation(self.probs, measure_value(measure, self.entropy, self.mutual_info, self.variance,
                                                     self.probs))

    def to_json(self) -> dict:
        if not self.ok:
            return {"ok": False, "probs": None, "entropy": None, "mutual_info": None, "variance": None}
        return {"ok": True, "probs": [float(v) for v in self.probs], "entropy": self.entropy,
                "mutual_info": self.mutual_info, "variance": [float(v) for v in self.variance]}


FAILED = RawOutputs(None, ok=False)


def _frame(space_n: int, action: int, conf: float, rng: np.random.Generator) -> RawOutputs:
    p = _probs_for(space_n, action, conf)
    p = p * rng.uniform(0.9, 1.1, size=space_n)
    p = p / p.sum()
    return RawOutputs(p, _entropy(p), float(rng.uniform(0.0, 0.3)), rng.uniform(0.0, 0.03, size=space_n))


def _scenarios(rng: np.random.Generator) -> list[tuple[str, DecisionConfig, list[tuple[float, float, RawOutputs | None]]]]:
    base = DecisionConfig()
    flat = RawOutputs(np.full(13, 1 / 13), math.log(13), 0.0, np.zeros(13))
    out = []
    sweep = [(i / FPS, 0.0, _frame(13, 1 + min(11, i * 12 // 90), 0.9, rng)) for i in range(100)]
    out.append(("sweep_left_to_right", base, sweep))
    out.append(("noise", base, [(i / FPS, 0.0, flat) for i in range(30)]))
    out.append(("unknown", base, [(i / FPS, 0.0, _frame(13, 0, 0.8, rng)) for i in range(30)]))
    odd = [(i / FPS, 0.0, _frame(13, 11 if i == 40 else 4, 0.9, rng)) for i in range(50)]
    out.append(("odd_frame", base, odd))
    hold = [(i / FPS, 0.0, _frame(13, 8, 0.95, rng)) for i in range(30)]
    hold += [((30 + i) / FPS, 25.0, flat) for i in range(75)]
    out.append(("hold_with_yaw_then_stop", base, hold))
    freeze = [(i / FPS, 0.0, _frame(13, 6, 0.9, rng)) for i in range(20)]
    freeze += [(20 / FPS + 0.05 * (j + 1), 0.0, None) for j in range(14)]
    out.append(("freeze_ticks_stale", base, freeze))
    fail = [(i / FPS, 0.0, _frame(13, 10, 0.9, rng)) for i in range(20)]
    fail[12] = (12 / FPS, 0.0, FAILED)
    out.append(("inference_failure", base, fail))
    jump = [(i / FPS, 0.0, _frame(13, 3 if i < 30 else 11, 0.97, rng)) for i in range(45)]
    out.append(("disagreement_jump", base, jump))
    turn = [(i / FPS, -60.0 if i >= 20 else 0.0, _frame(13, 2, 0.9, rng)) for i in range(40)]
    out.append(("fast_turn_goal_leaves_frame", base, turn))
    c4 = dataclasses.replace(base, n_actions=4)
    out.append(("four_actions", c4, [(i / FPS, 5.0, _frame(4, 1 + (i // 15) % 3, 0.85, rng))
                                      for i in range(45)]))
    c8 = dataclasses.replace(base, n_actions=8, measure="mutual_info", threshold=0.2)
    out.append(("eight_actions_mutual_info", c8, [(i / 15.0, 0.0, _frame(8, 1 + (i // 8) % 7, 0.8, rng))
                                                   for i in range(40)]))
    cv = dataclasses.replace(base, measure="variance", threshold=0.02)
    out.append(("variance_measure", cv, [(i / FPS, 0.0, _frame(13, 10, 0.9, rng)) for i in range(40)]))
    irregular = [(0.0, 0.0, _frame(13, 5, 0.9, rng))]
    t = 0.0
    for i in range(40):
        t += float(rng.uniform(0.01, 0.3))
        k = 9 if rng.uniform() < 0.7 else int(rng.integers(0, 13))
        obs = None if i % 7 == 3 else _frame(13, k, float(rng.uniform(0.5, 0.99)), rng)
        irregular.append((t, float(rng.uniform(-40, 40)), obs))
    out.append(("irregular_random", base, irregular))
    return out


def _config_json(cfg: DecisionConfig) -> dict:
    return dataclasses.asdict(cfg)


def _obs_json(raw: RawOutputs | None, measure: str) -> dict | None:
    if raw is None:
        return None
    obs = raw.observation(measure)
    return {**raw.to_json(), "uncertainty": obs.uncertainty if math.isfinite(obs.uncertainty) else None}


def build_vectors(seed: int = 20240601) -> dict:
    """All scenarios and beacon vectors as one JSON-ready dict."""
    rng = np.random.default_rng(seed)
    scenarios = []
    for name, cfg, steps in _scenarios(rng):
        d = Decider(cfg)
        rows = []
        for t, yaw, raw in steps:
            dec = d.step(t, None if raw is None else raw.observation(cfg.measure), yaw)
            rows.append({"t": t, "yaw_rate_dps": yaw, "obs": _obs_json(raw, cfg.measure), "expect": dec.to_json()})
        scenarios.append({"name": name, "config": _config_json(cfg), "steps": rows})
    bcfg = BeaconConfig()
    pans = [-1.0, -0.5, -0.1, 0.0, 0.3, 0.77, 1.0]
    headings = [-80.0, -45.0, -12.5, 0.0, 7.5, 30.0, 60.0]
    return {
        "version": VERSION,
        "generator": "python -m crossing_assist.runtime.vectors",
        "tolerance": 1e-9,
        "spec": "docs/runtime.md (Decision logic)",
        "scenarios": scenarios,
        "beacon": {
            "config": dataclasses.asdict(bcfg),
            "pan_gains": [{"pan": p, "left": pan_gains(p)[0], "right": pan_gains(p)[1]} for p in pans],
            "itd_seconds": [{"heading_deg": h, "itd_s": itd_seconds(h)} for h in headings],
            "heading_to_pan": [{"heading_deg": h, "fov_deg": 90.0, "pan": heading_to_pan(h, 45.0)} for h in headings],
            "loop_samples": [{"rate_hz": r, "samples": round(bcfg.sample_rate / r)} for r in (2.0, 3.3, 4.0, 6.0)],
        },
        "actions": {str(n): [list(g) for g in get_space(n).groups] for n in (4, 8, 13)},
    }


def write_vectors(path: str | Path, seed: int = 20240601) -> Path:
    """Write the vectors JSON atomically; returns the path."""
    return atomic_write_text(path, json.dumps(build_vectors(seed), allow_nan=False) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m crossing_assist.runtime.vectors", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("android_demo/test_vectors.json"))
    ap.add_argument("--seed", type=int, default=20240601)
    a = ap.parse_args(argv)
    try:
        path = write_vectors(a.out, a.seed)
    except OSError as exc:
        print(f"error: cannot write {a.out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    n = sum(len(s["steps"]) for s in json.loads(path.read_text())["scenarios"])
    print(f"wrote {path} ({n} decision steps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
