"""The one loop on the tiny lane: every registered algorithm runs, each shows its defining
behaviour, interventions and labels are counted exactly, every algorithm of an iteration gets
the same demonstration and start points, runs resume to the same numbers."""

import math

import numpy as np
import pytest
import torch

from crossing_assist.iil.algorithms import THESIS_ALGORITHMS, AlgoParams, create, list_algorithms
from crossing_assist.iil.data import Aggregate, EpisodeContext, Step
from crossing_assist.iil.envs import make_env
from crossing_assist.iil.experts import OracleExpert
from crossing_assist.iil.learners import LearnerConfig
from crossing_assist.iil.loop import EpisodeResult, Streams, aggregate_and_learn, run_episode, start_seed
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


def _episodes(name, n=3, horizon=H, seed=0, config="code", binary_risk=None):
    env = make_env("toy")
    streams = Streams.from_seed(seed)
    setup = create(name, env, horizon=horizon, episodes=n, seed=seed, cfg=TINY, params=AlgoParams(config=config))
    data, rows = Aggregate(), []
    for i in range(1, n + 1):
        res = run_episode(env, OracleExpert(env, binary_risk=binary_risk), setup, i, horizon, streams)
        rows.append({**res.metrics, **aggregate_and_learn(res, setup, data, streams.train), "trace": res.trace})
    return rows, data


def test_registry_holds_the_thesis_and_the_peers():
    names = list_algorithms()
    assert set(THESIS_ALGORITHMS) <= set(names)
    assert {"forward", "smile", "ensemble-dagger", "hg-dagger", "thrifty-dagger"} <= set(names)
    with pytest.raises(ValueError, match="Unknown algorithm"):
        create("nope", make_env("toy"), horizon=4, episodes=1, seed=0)


@pytest.mark.parametrize("config", ["thesis", "code"])
@pytest.mark.parametrize("name", list_algorithms())
def test_every_algorithm_runs_and_accounts_for_every_step(name, config):
    rows, data = _episodes(name, config=config, binary_risk=0.5 if config == "thesis" else None)
    for r in rows:
        assert r["steps"] == H
        assert r["interventions"] + r["learner_steps"] + r["explorer_steps"] == H
        assert 0 <= r["expert_labels"] <= H
        assert r["labels"] >= r["self_labels"] >= 0
        assert r["training_reward"] >= 0 and r["penalties"] >= 0
        assert r["reward"] == pytest.approx(r["training_reward"] - r["penalties"])
    assert len(data) == sum(r["labels"] for r in rows)
    assert rows[0]["interventions"] == H  # every algorithm starts from the expert's demonstration


def test_interventions_and_labels_are_separate_counts():
    """DAgger's expert labels every step but acts only when beta picks it (the thesis's queries
    are the interventions); supervised does both at every step."""
    rows, _ = _episodes("dagger", n=4)
    assert [r["expert_labels"] for r in rows] == [H] * 4
    assert rows[0]["interventions"] == H and sum(r["interventions"] for r in rows[1:]) < 3 * H
    for name in ("supervised",):
        rows, _ = _episodes(name)
        assert all(r["interventions"] == r["expert_labels"] == H for r in rows)
    for name in ("dropout-dagger", "ensemble-dagger"):
        rows, _ = _episodes(name)
        assert [r["expert_labels"] for r in rows] == [H] * 3, name


def test_upms_asks_only_when_the_expert_acts_and_sl_labels_every_step():
    rows, _ = _episodes("upms-ne", n=4)
    assert rows[0]["interventions"] == H and rows[0]["expert_labels"] == H
    assert all(r["expert_labels"] == r["interventions"] for r in rows)
    assert all(r["explorer_steps"] == 0 for r in rows)
    rows, _ = _episodes("upms-ne-sl", n=4)
    assert all(r["labels"] == H for r in rows)
    assert all(r["self_labels"] == r["learner_steps"] for r in rows)


def test_thesis_configuration_explores_with_the_0_inf_expert():
    """Eq. 19-21 with the 0/inf expert: UPMS's random explorer acts; UPMS-NE's E is the learner."""
    class Certain:  # a learner sure of itself (U = 0): a = tanh(30 * 0) = 0, so E' acts
        def act(self, obs, t, rng):
            return 0, 0.0

    env = make_env("toy")
    for name, explorer_acts in (("upms", True), ("upms-ne", False)):
        setup = create(name, env, horizon=32, episodes=3, seed=0, params=AlgoParams(config="thesis"), cfg=TINY)
        setup.learner = Certain()
        streams, expert = Streams.from_seed(0), OracleExpert(env, binary_risk=0.5)
        res = [run_episode(env, expert, setup, i, 32, streams).metrics for i in (1, 2, 3)]
        assert res[0]["interventions"] == 32 and res[0]["explorer_steps"] == 0
        late = res[1:]
        assert (sum(r["explorer_steps"] for r in late) > 0) == explorer_acts, name
        assert all(0 < r["interventions"] < 32 for r in late), name  # the expert acts when it is sure (U = 0)
    dd = create("dropout-dagger", env, horizon=H, episodes=2, seed=0, params=AlgoParams(config="thesis"), cfg=TINY)
    assert dd.mixing.threshold == 0.1 and dd.mixing.max_discrepancy is None  # sigma^2 = 0.1, no extra gate
    up = create("upms", env, horizon=H, episodes=2, seed=0, params=AlgoParams(config="thesis"), cfg=TINY)
    assert up.mixing.c_learner == up.sampling.c_learner == 30.0
    with pytest.raises(ValueError, match="Unknown configuration"):
        create("upms", env, horizon=H, episodes=2, seed=0, params=AlgoParams(config="nope"))


def test_every_algorithm_gets_the_same_demonstration_and_start_points():
    """One seed per iteration: episode 1 (the expert's) is the same trace for every algorithm,
    and episode 2 starts from the same pre-computed start point."""
    got = {}
    for name in ("supervised", "dagger", "aggrevate", "dropout-dagger", "upms", "upms-sl"):
        rows, _ = _episodes(name, n=2, seed=4, config="thesis", binary_risk=0.5)
        tr = rows[0]["trace"]
        got[name] = ([s.action for s in tr], [s.reward for s in tr], rows[1]["trace"][0].obs)
    first = next(iter(got.values()))
    for name, (actions, rewards, start2) in got.items():
        assert actions == first[0] and rewards == first[1], name
        assert np.array_equal(start2, first[2]), name
    assert start_seed(4, 2, 0) == start_seed(4, 2, 0) != start_seed(4, 2, 1) != start_seed(5, 2, 1)


def test_the_learner_trains_on_all_of_d():
    rows, data = _episodes("supervised", n=3)
    assert rows[-1]["samples"] == len(data) == 3 * H  # no truncation (max_samples None)


def test_aggrevate_explores_exactly_once_after_the_first_episode():
    rows, _ = _episodes("aggrevate", n=3)  # (code config; AggreVaTe is the same in both)
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


@pytest.mark.parametrize("name, expert_labels, labels, self_labels", [
    ("dagger", 3, 3, 0),         # every step the expert answered is a label
    ("upms-ne", 1, 1, 0),        # only the step the expert acted with an action
    ("upms-ne-sl", 1, 5, 4),     # ... and the learner labels the other four itself
    ("hg-dagger", 1, 1, 0),
])
def test_label_counting_is_exact(name, expert_labels, labels, self_labels):
    env = make_env("toy")
    setup = create(name, env, horizon=5, episodes=2, seed=0, cfg=TINY, params=AlgoParams(config="code"))
    out = aggregate_and_learn(EpisodeResult({}, _trace(), EpisodeContext(2, 5)), setup, Aggregate(),
                              np.random.default_rng(0))
    assert (out["expert_labels"], out["labels"], out["self_labels"]) == (expert_labels, labels, self_labels)


def _strip(rows):
    return [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()
             if not k.startswith("seconds")} for r in rows]


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


def test_baselines_are_the_same_in_both_configurations():
    """Supervised, DAgger and AggreVaTe ignore the expert's uncertainty and every UPMS setting:
    the report may show one set of their runs in both configurations' tables."""
    for name in ("supervised", "dagger", "aggrevate"):
        a, _ = _episodes(name, n=3, seed=2, config="thesis", binary_risk=0.5)
        b, _ = _episodes(name, n=3, seed=2, config="code")
        strip = lambda rows: [{k: v for k, v in r.items() if k not in ("trace", "mean_u_expert")  # noqa: E731
                               and not k.startswith("seconds")} for r in rows]
        assert strip(a) == strip(b), name
