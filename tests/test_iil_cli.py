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
    for config in ("thesis", "code"):
        r = _run("run", "--env", "toy", "--algo", "dagger,upms-sl", "--episodes", "2", "--horizon", "6",
                 "--seeds", "1", "2", "--out", out, "--epochs", "1", "--mc-samples", "2", "--quiet", "--config", config)
        assert r.returncode == 0, r.stderr
        assert "done: 4 run(s)" in r.stdout
    rows = list(csv.DictReader((out / "toy" / "thesis" / "dagger" / "seed2" / "episodes.csv").open()))
    assert [int(x["episode"]) for x in rows] == [1, 2] and all(int(x["expert_labels"]) == 6 for x in rows)
    meta = (out / "toy" / "thesis" / "dagger" / "seed2" / "config.json").read_text()
    assert '"binary_risk": 0.5' in meta  # the thesis configuration's 0/inf expert
    assert '"binary_risk": null' in (out / "toy" / "code" / "dagger" / "seed2" / "config.json").read_text()
    rep = tmp_path / "rep"
    r = _run("report", out, "--out", rep)
    assert r.returncode == 0, r.stderr
    table = (rep / "table3.md").read_text()
    assert "## toy, configuration `thesis`" in table and "## toy, configuration `code`" in table
    assert "| dagger | 2 | 12 |" in table and "upms-sl" in table and "3175.94 ± 14.63" in table
    assert "| 12.0 ± 0.0 |" in table  # DAgger: the expert labels all 12 steps of a run
    for config in ("thesis", "code"):
        for metric in ("training_reward", "interventions", "penalties", "out_of_bounds"):
            png = rep / f"fig_toy_{config}_{metric}.png"
            assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert list(csv.DictReader((rep / "table3.csv").open()))[0]["algorithm"] == "dagger"


@pytest.mark.parametrize("args, message", [
    (["run", "--env", "toy", "--algo", "nope", "--out", "x"], "unknown algorithm 'nope'"),
    (["run", "--env", "toy", "--algo", "dagger", "--episodes", "0", "--out", "x"], "--episodes=0"),
    (["run", "--env", "toy", "--algo", "dagger", "--dagger-p", "1.5", "--out", "x"], "--dagger-p=1.5"),
    (["report", "does-not-exist"], "does-not-exist: no such folder"),
    (["run", "--env", "crossing", "--algo", "dagger", "--frame-size", "80", "60", "--out", "x"], "duckietown only"),
    (["run", "--env", "duckietown", "--algo", "dagger", "--expert", "human", "--out", "x"], "discrete actions"),
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
    from crossing_assist.iil.algorithms import AlgoParams

    assert a.dagger_p == AlgoParams().dagger_p and a.config == AlgoParams().config == "thesis"
    assert learner.mc_samples == 16 and learner.max_samples is None and a.max_samples is None


def test_human_expert_in_a_real_window(tmp_path, monkeypatch):
    """``--expert human`` opens a real pygame window (SDL's dummy driver here) that shows every
    frame; synthetic key events posted to its queue drive the expert; closing the window stops
    the run after the last finished episode (and the same command resumes it)."""
    pg = pytest.importorskip("pygame")
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    import numpy as np

    from crossing_assist.iil import experts
    from crossing_assist.iil.cli import main

    script = {0: [(pg.KEYDOWN, pg.K_5)], 4: [(pg.KEYUP, pg.K_5)], 5: [(pg.KEYDOWN, pg.K_MINUS)],
              6: [(pg.KEYUP, pg.K_MINUS)], 12: [(pg.QUIT, None)]}
    seen = {"polls": 0, "frames": []}
    poll = experts.PygameWindow.poll

    def scripted_poll(self):
        for kind, key in script.get(seen["polls"], []):
            pg.event.post(pg.event.Event(kind, key=key) if key is not None else pg.event.Event(kind))
        seen["polls"] += 1
        seen["frames"].append(self.frames)
        return poll(self)

    monkeypatch.setattr(experts.PygameWindow, "poll", scripted_poll)
    args = ["run", "--env", "crossing-synthetic", "--algo", "upms-ne", "--expert", "human", "--episodes", "2",
            "--horizon", "8", "--fps", "1000", "--seeds", "1", "--out", str(tmp_path), "--quiet", "--epochs", "1",
            "--mc-samples", "2"]
    assert main(args) == 130  # the window was closed during episode 2
    assert seen["frames"][:3] == [1, 2, 3]  # each step showed its frame before reading the keys
    folder = tmp_path / "crossing-synthetic" / "thesis" / "upms-ne" / "seed1"
    rows = list(csv.DictReader((folder / "episodes.csv").open()))
    assert len(rows) == 1 and int(rows[0]["interventions"]) == 8  # episode 1 is the expert's
    with np.load(folder / "data" / "ep1.npz") as z:
        assert z["labels"].tolist() == [5, 5, 5, 5, 11] and z["steps"].tolist() == [0, 1, 2, 3, 5]
