"""The one loop on the tiny lane: every registered algorithm runs, each shows its defining
behaviour, queries are counted exactly, runs resume to the same numbers."""

import math

import numpy as np
import pytest
import torch

from crossing_assist.iil.algorithms import THESIS_ALGORITHMS, create, list_algorithms
from crossing_assist.iil.data import Aggregate, Step
from crossing_assist.iil.envs import make_env
from crossing_assist.iil.experts import OracleExpert
from crossing_assist.iil.learners import LearnerConfig
from crossing_assist.iil.loop import EpisodeResult, aggregate_and_learn, run_episode
from crossing_assist.iil.mixing import EXPERT, EXPLORER, LEARNER
from crossing_assist.iil.runner import RunConfig, RunError, read_episodes, run

TINY = LearnerConfig(epochs=1, mc_samples=3, ensemble=2, batch_size=8, channels=4, hidden=8)
H = 8


@pytest.fixture(autouse=True)
def one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def _episodes(name, n=3, horizon=H, seed=0):
    env = make_env("toy")
    rng = np.random.default_rng(seed)
    setup = create(name, env, horizon=horizon, episodes=n, seed=seed, cfg=TINY)
    data, rows = Aggregate(), []
    for i in range(1, n + 1):
        res = run_episode(env, OracleExpert(env), setup, i, horizon, rng)
        rows.append({**res.metrics, **aggregate_and_learn(res, setup, data, i, rng), "trace": res.trace})
    return rows, data


def test_registry_holds_the_thesis_and_the_peers():
    names = list_algorithms()
    assert set(THESIS_ALGORITHMS) <= set(names)
    assert {"forward", "smile", "ensemble-dagger", "hg-dagger", "thrifty-dagger"} <= set(names)
    with pytest.raises(ValueError, match="Unknown algorithm"):
        create("nope", make_env("toy"), horizon=4, episodes=1, seed=0)


@pytest.mark.parametrize("name", list_algorithms())
def test_every_algorithm_runs_and_accounts_for_every_step(name):
    rows, data = _episodes(name)
    for r in rows:
        assert r["steps"] == H
        assert r["expert_steps"] + r["learner_steps"] + r["explorer_steps"] == H
        assert 0 <= r["queries"] <= H
        assert r["labels"] >= r["self_labels"] >= 0
    assert len(data) == sum(r["labels"] for r in rows)
    assert rows[0]["expert_steps"] == H  # every algorithm starts from the expert's demonstration


def test_supervised_and_dagger_query_every_step():
    for name in ("supervised", "dagger", "dropout-dagger", "ensemble-dagger"):
        rows, _ = _episodes(name)
        assert [r["queries"] for r in rows] == [H] * 3, name
    rows, _ = _episodes("supervised")
    assert all(r["expert_steps"] == H for r in rows)


def test_upms_asks_only_when_the_expert_acts_and_sl_labels_every_step():
    rows, _ = _episodes("upms-ne", n=4)
    assert rows[0]["expert_steps"] == H and rows[0]["queries"] == H
    assert all(r["queries"] == r["expert_steps"] for r in rows)
    assert all(r["explorer_steps"] == 0 for r in rows)
    rows, _ = _episodes("upms-ne-sl", n=4)
    assert all(r["labels"] == H for r in rows)
    assert all(r["self_labels"] == r["learner_steps"] for r in rows)


def test_aggrevate_explores_exactly_once_after_the_first_episode():
    rows, _ = _episodes("aggrevate", n=3)
    assert rows[0]["explorer_steps"] == 0
    for r in rows[1:]:
        actors = [s.actor for s in r["trace"]]
        assert actors.count(EXPLORER) == 1
        k = actors.index(EXPLORER)
        assert all(a == EXPERT for a in actors[k + 1:])
        assert math.isfinite(r["cost_to_go"])


def test_forward_training_hands_trained_blocks_to_the_learner():
    rows, _ = _episodes("forward", n=3, horizon=H)  # block = ceil(8 / 3) = 3 steps
    assert [r["learner_steps"] for r in rows] == [0, 3, 6]
    assert [r["labels"] for r in rows] == [3, 3, 2]


def _trace():
    obs = np.zeros((4, 4, 3), np.uint8)
    mk = lambda t, a_exp, actor: Step(t, obs, a_exp, 0.5, 1, 0.1, actor, 1, 0.0, False, actor == EXPERT)  # noqa: E731
    return [mk(0, 2, EXPERT), mk(1, 2, LEARNER), mk(2, None, LEARNER), mk(3, None, EXPERT), mk(4, 0, EXPLORER)]


@pytest.mark.parametrize("name, queries, labels, self_labels", [
    ("dagger", 3, 3, 0),         # every step the expert answered is a label, hence a query
    ("upms-ne", 1, 1, 0),        # only the step the expert acted with an action
    ("upms-ne-sl", 1, 5, 4),     # ... and the learner labels the other four itself
    ("hg-dagger", 1, 1, 0),
])
def test_query_counting_is_exact(name, queries, labels, self_labels):
    env = make_env("toy")
    setup = create(name, env, horizon=5, episodes=2, seed=0, cfg=TINY)
    out = aggregate_and_learn(EpisodeResult({}, _trace()), setup, Aggregate(), 2, np.random.default_rng(0))
    assert (out["queries"], out["labels"], out["self_labels"]) == (queries, labels, self_labels)


def _strip(rows):
    return [{k: v for k, v in r.items() if not k.startswith("seconds")} for r in rows]


def test_runs_resume_to_the_same_numbers(tmp_path):
    cfg = RunConfig(env="toy", algo="upms", seed=5, episodes=3, horizon=H, learner=TINY)
    whole = run(cfg, tmp_path / "a")
    part = RunConfig(env="toy", algo="upms", seed=5, episodes=2, horizon=H, learner=TINY)
    run(part, tmp_path / "b")
    assert len(read_episodes(part.folder(tmp_path / "b") / "episodes.csv")) == 2
    resumed = run(cfg, tmp_path / "b")
    a, b = read_episodes(whole / "episodes.csv"), read_episodes(resumed / "episodes.csv")
    assert len(a) == 3 and _strip(a) == _strip(b)
    cfg_json = (whole / "config.json").read_text()
    assert '"seed": 5' in cfg_json and '"torch"' in cfg_json and '"strategies"' in cfg_json


def test_a_folder_with_another_config_is_refused(tmp_path):
    run(RunConfig(env="toy", algo="dagger", seed=1, episodes=1, horizon=4, learner=TINY), tmp_path)
    with pytest.raises(RunError, match="different horizon"):
        run(RunConfig(env="toy", algo="dagger", seed=1, episodes=1, horizon=6, learner=TINY), tmp_path)
