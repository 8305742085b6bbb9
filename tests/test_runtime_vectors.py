"""The shared decision vectors (android_demo/test_vectors.json) are current and replayable from
their JSON alone, which is all the phone app gets."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from crossing_assist.runtime import belief as bf
from crossing_assist.runtime.decide import Decider, DecisionConfig, Observation
from crossing_assist.runtime.gate import GateConfig
from crossing_assist.runtime.vectors import build_vectors, main

VECTORS = Path(__file__).resolve().parents[1] / "android_demo" / "test_vectors.json"


@pytest.fixture(scope="module")
def stored():
    if not VECTORS.is_file():
        pytest.fail(f"{VECTORS} is missing; run python -m crossing_assist.runtime.vectors")
    return json.loads(VECTORS.read_text())


def test_stored_vectors_match_the_current_logic(stored):
    fresh = json.loads(json.dumps(build_vectors()))
    assert _same(fresh, stored, 1e-9), "decision logic changed: regenerate android_demo/test_vectors.json"


def _same(a, b, tol) -> bool:
    """Equal JSON trees, floats within ``tol`` (last-bit libm differences across platforms)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k], tol) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same(x, y, tol) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=tol, abs_tol=tol)
    return a == b


def _config(d: dict) -> DecisionConfig:
    d = dict(d)
    d["filter"] = bf.FilterConfig(**d["filter"])
    d["gate"] = GateConfig(**d["gate"])
    return DecisionConfig(**d)


def _close(a, b, tol):
    if isinstance(a, list):
        return len(a) == len(b) and all(_close(x, y, tol) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return a is not None and b is not None and math.isclose(a, b, rel_tol=tol, abs_tol=tol)
    return a == b


def test_vectors_replay_from_json_alone(stored):
    kinds = set()
    for sc in stored["scenarios"]:
        d = Decider(_config(sc["config"]))
        for row in sc["steps"]:
            o = row["obs"]
            obs = None
            if o is not None and o["ok"]:  # the port starts from the graph's raw outputs
                measure = sc["config"]["measure"]
                u = (o["entropy"] if measure == "entropy" else o["mutual_info"] if measure == "mutual_info"
                     else o["variance"][int(np.argmax(o["probs"]))])
                assert u == o["uncertainty"]
                obs = Observation(np.array(o["probs"]), u)
            elif o is not None:
                obs = Observation(None, math.inf, ok=False)
            got = d.step(row["t"], obs, row["yaw_rate_dps"]).to_json()
            for key, want in row["expect"].items():
                assert _close(got[key], want, stored["tolerance"]), (sc["name"], row["t"], key)
            kinds.add((row["expect"]["gate"], row["expect"]["reason"]))
    # the vectors exercise every gate state and every stop reason
    assert {("learner", "ok"), ("hold", "ok"), ("stop", "uncertain"), ("stop", "stale"), ("stop", "failed")} <= kinds


def test_cli_writes_the_file(tmp_path, capsys):
    assert main(["--out", str(tmp_path / "v.json")]) == 0
    assert json.loads((tmp_path / "v.json").read_text())["version"] == 1
    assert "decision steps" in capsys.readouterr().out
