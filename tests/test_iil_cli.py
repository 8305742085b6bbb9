"""crossing-iil through a subprocess: a tiny run, resuming, the report, and user errors."""

import csv
import subprocess
import sys

import pytest

from crossing_assist.iil.envs.duckietown import duckietown_available

CLI = [sys.executable, "-m", "crossing_assist.iil.cli"]


def _run(*args, cwd=None):
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd)


def test_run_then_report(tmp_path):
    out = tmp_path / "runs"
    r = _run("run", "--env", "toy", "--algo", "dagger,upms-sl", "--episodes", "2", "--horizon", "6",
             "--seeds", "1", "2", "--out", out, "--epochs", "1", "--mc-samples", "2", "--quiet")
    assert r.returncode == 0, r.stderr
    assert "done: 4 run(s)" in r.stdout
    rows = list(csv.DictReader((out / "toy" / "dagger" / "seed2" / "episodes.csv").open()))
    assert [int(x["episode"]) for x in rows] == [1, 2] and all(int(x["queries"]) == 6 for x in rows)
    rep = tmp_path / "rep"
    r = _run("report", out, "--out", rep)
    assert r.returncode == 0, r.stderr
    table = (rep / "table3.md").read_text()
    assert "| toy | dagger | 2 | 2 |" in table and "upms-sl" in table
    assert "| 6.0 ± 0.0 |" in table  # DAgger: the expert labels all 6 steps of every episode
    for metric in ("reward", "queries", "penalties", "out_of_bounds"):
        png = rep / f"fig_toy_{metric}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert list(csv.DictReader((rep / "table3.csv").open()))[0]["algorithm"] == "dagger"


@pytest.mark.parametrize("args, message", [
    (["run", "--env", "toy", "--algo", "nope", "--out", "x"], "unknown algorithm 'nope'"),
    (["run", "--env", "toy", "--algo", "dagger", "--episodes", "0", "--out", "x"], "--episodes=0"),
    (["report", "does-not-exist"], "does-not-exist: no such folder"),
])
def test_user_errors_get_one_line(tmp_path, args, message):
    r = _run(*args, cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.startswith("error: ") and message in r.stderr and "Traceback" not in r.stderr


@pytest.mark.skipif(duckietown_available()[0], reason="Duckietown is available here: the run would start")
def test_duckietown_unavailable_is_one_line(tmp_path):
    r = _run("run", "--env", "duckietown", "--algo", "dagger", "--out", tmp_path / "o", "--quiet")
    assert r.returncode == 2 and r.stderr.startswith("error: Duckietown is not available here")
    assert not (tmp_path / "o").exists()


def test_cli_defaults_match_the_config_dataclasses():
    from crossing_assist.iil.cli import build_parser
    from crossing_assist.iil.config import LearnerConfig
    from crossing_assist.iil.runner import RunConfig

    a = build_parser().parse_args(["run", "--env", "toy", "--algo", "dagger", "--out", "x"])
    run, learner = RunConfig(env="toy", algo="dagger", seed=1), LearnerConfig()
    assert (a.episodes, a.horizon) == (run.episodes, run.horizon) == (10, 512)
    assert (a.lr, a.epochs, a.mc_samples, a.ensemble) == (learner.lr, learner.epochs, learner.mc_samples,
                                                          learner.ensemble)
    assert a.lr == 1e-3  # the thesis's AdaGrad learning rate
