"""The typed seams of the IIL package: every environment, learner and expert meets its
protocol, algorithm names live in one catalogue, the CLI's defaults are the typed configs'."""

import numpy as np
import pytest

from crossing_assist.iil import config
from crossing_assist.iil.algorithms import AlgoParams, Parts, create, list_algorithms, register
from crossing_assist.iil.data import EpisodeContext, Label, Step
from crossing_assist.iil.envs import ENV_NAMES, make_env
from crossing_assist.iil.experts import OracleExpert
from crossing_assist.iil.learners import LearnerConfig
from crossing_assist.iil.protocols import Expert, IILDefaults, IILEnv, Learner, RiskCritic, iil_env

TINY = LearnerConfig(epochs=1, mc_samples=2, ensemble=2, batch_size=8, channels=4, hidden=8)


@pytest.mark.parametrize("name", [n for n in ENV_NAMES if n != "duckietown"])  # duckietown: its own venv
def test_environments_meet_the_iil_env_protocol(name):
    env = make_env(name)
    inner = iil_env(env)
    assert isinstance(inner, IILEnv) and isinstance(inner.iil_defaults, IILDefaults)
    env.reset(seed=0)
    action, risk = inner.oracle()
    assert env.action_space.contains(action) and 0.0 <= risk <= 1.0
    assert env.action_space.contains(inner.safe_action())
    _, _, _, _, info = env.step(action)
    assert isinstance(info["out_of_bounds"], bool) and isinstance(info["reward_terms"], dict)


def test_an_environment_without_the_contract_is_refused_by_name():
    class Bare:
        unwrapped = None

    Bare.unwrapped = Bare()
    with pytest.raises(TypeError, match="lacks oracle, safe_action, iil_defaults"):
        OracleExpert(Bare())
    with pytest.raises(TypeError, match="lacks oracle"):
        AlgoParams().resolved(Bare())


def test_make_env_takes_no_horizon_and_names_the_valid_ones():
    with pytest.raises(TypeError):
        make_env("toy", horizon=512)  # the loop owns the horizon; no environment takes one
    with pytest.raises(ValueError, match="valid: toy, crossing, crossing-synthetic, duckietown"):
        make_env("nope")


def test_defaults_come_from_the_environment_only_where_unset():
    env = make_env("toy")
    p = AlgoParams(learner_threshold=0.25).resolved(env)
    d = env.unwrapped.iil_defaults
    assert (p.expert_threshold, p.learner_threshold, p.hg_threshold, p.max_discrepancy) == (
        d.expert_threshold, 0.25, d.hg_threshold, None)


@pytest.mark.parametrize("name", list_algorithms())
def test_every_algorithm_is_named_once_and_its_parts_are_typed(name):
    env = make_env("toy")
    setup = create(name, env, horizon=6, episodes=2, seed=0, cfg=TINY, params=AlgoParams(config="code"))
    assert setup.name == name and setup.describe()["algorithm"] == name
    assert isinstance(setup.learner, Learner)
    assert isinstance(OracleExpert(env), Expert)
    if name == "thrifty-dagger":
        assert isinstance(setup.learner, RiskCritic)


def test_the_catalogue_and_the_registry_agree():
    assert list_algorithms() == list(config.ALGORITHMS)
    assert set(config.THESIS_ALGORITHMS) <= set(config.ALGORITHMS)
    from crossing_assist.iil import report  # torch-free: reads the same catalogue

    assert tuple(report.ORDER) == config.ALGORITHMS
    with pytest.raises(ValueError, match="list it in"):
        register("not-in-the-catalogue")
    with pytest.raises(ValueError, match="already registered"):
        register("dagger")(lambda **_: Parts(None, None, None, None))


def test_labels_and_context_are_named_records():
    lab = Label(3, 7)
    assert (lab.index, lab.action, lab.weight, lab.self_labelled) == (3, 7, 1.0, False)
    ctx = EpisodeContext(i=2, horizon=10)
    assert ctx.switch_time is None and ctx.cost_to_go is None


def test_aggrevate_passes_its_switch_time_through_the_context():
    env = make_env("toy")
    setup = create("aggrevate", env, horizon=6, episodes=2, seed=0, cfg=TINY)
    ctx = EpisodeContext(2, 6)
    setup.sampling.begin_episode(ctx, np.random.default_rng(1))
    assert 0 <= ctx.switch_time < 6
    obs = np.zeros((4, 4, 3), np.uint8)
    trace = [Step(t, obs, 1, 0.0, 1, 0.1, "expert", 1, -1.0, False, True) for t in range(6)]
    labels = setup.aggregation.select(trace, ctx)
    assert [lab.index for lab in labels] == list(range(ctx.switch_time, 6))
    assert ctx.cost_to_go == -(6 - ctx.switch_time)
    assert labels[0].weight == 1.0 + min(4.0, (6 - ctx.switch_time) / 10.0)
    assert all(lab.weight == 1.0 for lab in labels[1:])


def test_cli_defaults_are_the_typed_configs():
    from crossing_assist.iil.cli import build_parser

    a = build_parser().parse_args(["run", "--env", "toy", "--algo", "dagger", "--out", "x"])
    run, algo, learner = config.RunConfig(env="toy", algo="dagger", seed=1), AlgoParams(), LearnerConfig()
    assert (a.episodes, a.horizon, a.expert) == (run.episodes, run.horizon, run.expert)
    assert run.horizon == config.THESIS_HORIZON
    assert (a.config, a.dagger_p) == (algo.config, algo.dagger_p)
    assert (a.lr, a.epochs, a.mc_samples, a.ensemble, a.max_samples) == (
        learner.lr, learner.epochs, learner.mc_samples, learner.ensemble, learner.max_samples)


def test_sweep_builds_the_same_configs_as_run():
    from crossing_assist.iil.cli import build_parser, run_configs

    args = ["--env", "toy", "--algo", "dagger", "upms", "--out", "x", "--config", "code", "--dagger-p", "0.3",
            "--max-samples", "50", "--seeds", "1", "2"]
    p = build_parser()
    run_cfgs, sweep_cfgs = run_configs(p.parse_args(["run", *args])), run_configs(p.parse_args(["sweep", *args]))
    assert run_cfgs == sweep_cfgs and len(run_cfgs) == 4
    assert all(c.params.config == "code" and c.params.dagger_p == 0.3 and c.learner.max_samples == 50
               for c in run_cfgs)
