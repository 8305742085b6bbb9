"""crossing-iil sweep: runs as Ray tasks on a local 2-CPU Ray give the sequential runner's numbers;
finished runs are skipped; without Ray, one error line."""

import json
import math
import os
import subprocess
import sys

import pytest
import torch

from crossing_assist.iil.files import read_episodes

CLI = [sys.executable, "-c", "import sys; from crossing_assist.iil.cli import main; sys.exit(main(sys.argv[1:]))"]
ARGS = ["--env", "crossing", "--algo", "dagger", "upms", "--seeds", "1", "2", "--episodes", "2", "--horizon", "16",
        "--threads", "1", "--quiet"]


def _numbers(folder):
    """episodes.csv without the wall-clock columns (NaN, e.g. the mean of no finite expert
    uncertainty, written as "nan" so that equal runs compare equal), and the learner's final weights."""
    nan = lambda v: "nan" if isinstance(v, float) and math.isnan(v) else v  # noqa: E731
    rows = [{k: nan(v) for k, v in r.items() if not k.startswith("seconds")} for r in read_episodes(folder / "episodes.csv")]
    return rows, torch.load(folder / "state.pt", weights_only=True)["learner"]


def _same(a, b) -> bool:
    """Nested state (dicts, lists, tensors) equal bit for bit."""
    if torch.is_tensor(a):
        return torch.is_tensor(b) and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def test_sweep_on_local_ray_matches_sequential_runner_and_skips_finished(tmp_path):
    pytest.importorskip("ray")
    from crossing_assist.iil.runner import RunConfig, run
    from crossing_assist.iil.sweep import sweep

    configs = [RunConfig(env="crossing", algo=a, seed=s, episodes=2, horizon=16) for a in ("dagger", "upms")
               for s in (1, 2)]
    torch.set_num_threads(1)
    for c in configs:
        run(c, tmp_path / "seq")
    res = sweep(configs, tmp_path / "ray", cpus=2, log=lambda *_: None)
    assert sorted(res["ran"]) == sorted(str(c.folder((tmp_path / "ray").resolve())) for c in configs)
    for c in configs:
        rows_a, sd_a = _numbers(c.folder(tmp_path / "seq"))
        rows_b, sd_b = _numbers(c.folder(tmp_path / "ray"))
        assert rows_a == rows_b and len(rows_b) == 2
        assert _same(sd_a, sd_b)
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "ray").rglob("*") if p.is_file()}
    # the CLI builds the same configurations: all four are finished, nothing runs, nothing is rewritten
    r = subprocess.run([*CLI, "sweep", *ARGS, "--out", str(tmp_path / "ray")], capture_output=True, text=True,
                       env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert r.returncode == 0, r.stderr
    assert "0 run(s) as Ray tasks, 4 already finished" in r.stdout
    assert stamps == {p: p.stat().st_mtime_ns for p in (tmp_path / "ray").rglob("*") if p.is_file()}
    assert json.loads((c.folder(tmp_path / "ray") / "config.json").read_text())["run"]["seed"] == 2


def test_sweep_without_ray_is_one_error_line(tmp_path):
    code = ("import sys; sys.modules['ray'] = None; from crossing_assist.iil.cli import main; "
            "sys.exit(main(sys.argv[1:]))")
    r = subprocess.run([sys.executable, "-c", code, "sweep", *ARGS, "--out", str(tmp_path / "x")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.startswith("error:") and "pip install" in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr
