"""The mixing and sampling laws, exactly: UPMS's consistency, rationality, neutrality and
impossibility; DAgger's beta schedule; SMILe's geometric mixture; the sampling strategies."""

import math

import numpy as np
import pytest

from crossing_assist.iil.data import EpisodeContext
from crossing_assist.iil.mixing import (EXPERT, EXPLORER, LEARNER, BetaDecay, ExpertGate, GeometricMixture,
                                        LearnerThreshold, PerStepSchedule, RationalMixing, StepView, ThriftyGate,
                                        action_distance, beta_schedule, coefficient, rational_mixing, saturation)
from crossing_assist.iil.sampling import FullHorizon, RandomSwitch, RationalSampling

GRID = [0.0, 0.01, 0.1, 0.5, 1.0, 2.0, 10.0, math.inf]


def test_coefficient_is_one_minus_tanh_and_half_at_threshold():
    c = saturation(0.2)
    assert coefficient(0.2, c) == pytest.approx(0.5, abs=1e-12)
    assert coefficient(0.0, c) == 1.0
    assert coefficient(math.inf, c) == 0.0
    assert coefficient(0.7, 3.0) == pytest.approx(1 - math.tanh(2.1), abs=1e-15)
    with pytest.raises(ValueError):
        saturation(0.0)
    # the mixing law uses the one shared coefficient (crossing_assist.upms; its contract is tested there)
    from crossing_assist import upms
    from crossing_assist.runtime import gate

    assert coefficient is upms.coefficient is gate.alpha


@pytest.mark.parametrize("ut", GRID)
@pytest.mark.parametrize("ul", GRID)
def test_consistency(ut, ul):
    p = rational_mixing(ut, ul, 1.3, 0.7)
    assert 0.0 <= p <= 1.0
    q_learner = 1.0 - p
    assert p + q_learner == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("u", GRID[:-1])
def test_neutrality(u):
    assert rational_mixing(u, u, 2.0, 2.0) == pytest.approx(0.5, abs=1e-15)


def test_rationality_less_uncertain_agent_is_more_likely():
    c = 1.0
    for lo, hi in [(0.0, 0.1), (0.1, 1.0), (0.5, 3.0), (1.0, math.inf)]:
        assert rational_mixing(lo, hi, c, c) > 0.5  # expert less uncertain -> expert favoured
        assert rational_mixing(hi, lo, c, c) < 0.5
    ps = [rational_mixing(u, 0.5, c, c) for u in GRID]
    assert all(a >= b for a, b in zip(ps, ps[1:]))  # monotone in the expert's uncertainty
    assert rational_mixing(0.3, 0.9, c, c) == pytest.approx(
        (1 - math.tanh(0.3)) / ((1 - math.tanh(0.3)) + (1 - math.tanh(0.9))), abs=1e-15)


def test_impossibility_hands_control_to_the_expert():
    assert rational_mixing(math.inf, math.inf, 1.0, 1.0) == 1.0
    mix = RationalMixing(expert_threshold=1.0, learner_threshold=1.0)
    rng = np.random.default_rng(0)
    view = StepView(i=3, t=0, u_expert=math.inf, u_learner=math.inf)
    assert all(mix.choose(view, rng) == (EXPERT, 1.0) for _ in range(50))
    # only the learner answers -> the learner, with certainty
    view = StepView(i=3, t=0, u_expert=math.inf, u_learner=0.2)
    assert all(mix.choose(view, rng) == (LEARNER, 1.0) for _ in range(50))


def test_rational_mixing_frequency_matches_the_law():
    mix = RationalMixing(expert_threshold=1.0, learner_threshold=1.0)
    rng = np.random.default_rng(1)
    view = StepView(i=2, t=0, u_expert=0.5, u_learner=1.5)
    p = rational_mixing(0.5, 1.5, mix.c_expert, mix.c_learner)
    n = 4000
    hits = sum(mix.choose(view, rng)[0] == EXPERT for _ in range(n))
    # 6 standard deviations: a false failure has probability < 1e-8
    assert abs(hits / n - p) < 6 * math.sqrt(p * (1 - p) / n)


def test_first_episode_is_the_experts():
    rng = np.random.default_rng(0)
    view = StepView(i=1, t=0, u_expert=math.inf, u_learner=0.0)
    assert RationalMixing(1.0, 1.0).choose(view, rng) == (EXPERT, 1.0)
    assert LearnerThreshold(1.0).choose(view, rng) == (EXPERT, 1.0)


def test_beta_schedule_exact():
    assert [beta_schedule(i, 0.5) for i in range(1, 5)] == [1.0, 0.5, 0.25, 0.125]
    assert beta_schedule(1, 0.0) == 1.0 and beta_schedule(2, 0.0) == 0.0
    with pytest.raises(ValueError):
        beta_schedule(0, 0.5)
    rng = np.random.default_rng(0)
    assert all(BetaDecay(0.5).choose(StepView(1, 0, 0.0, 0.0), rng)[0] == EXPERT for _ in range(100))
    assert all(BetaDecay(0.0).choose(StepView(2, 0, 0.0, 0.0), rng)[0] == LEARNER for _ in range(100))
    n, hits = 4000, sum(BetaDecay(0.5).choose(StepView(3, 0, 0.0, 0.0), rng)[0] == EXPERT for _ in range(4000))
    assert abs(hits / n - 0.25) < 6 * math.sqrt(0.25 * 0.75 / n)  # false failure < 1e-8


def test_smile_geometric_expert_probability():
    mix = GeometricMixture(alpha=1.0)
    rng = np.random.default_rng(0)
    assert mix.choose(StepView(1, 0, 0.0, 0.0), rng)[0] == EXPERT
    assert mix.choose(StepView(2, 0, 0.0, 0.0), rng)[0] == LEARNER


def test_threshold_gates():
    rng = np.random.default_rng(0)
    gate = LearnerThreshold(0.1, max_discrepancy=0.0)
    assert gate.choose(StepView(2, 0, 0.0, 0.05, expert_action=3, learner_action=3), rng)[0] == LEARNER
    assert gate.choose(StepView(2, 0, 0.0, 0.05, expert_action=4, learner_action=3), rng)[0] == EXPERT
    assert gate.choose(StepView(2, 0, 0.0, 0.2, expert_action=3, learner_action=3), rng)[0] == EXPERT
    hg = ExpertGate(0.5)
    assert hg.choose(StepView(2, 0, 0.4, 9.0, expert_action=1), rng)[0] == EXPERT
    assert hg.choose(StepView(2, 0, 0.6, 9.0, expert_action=1), rng)[0] == LEARNER
    fwd = PerStepSchedule(block=5)
    assert [fwd.choose(StepView(3, t, 0, 0), rng)[0] for t in (0, 9, 10)] == [LEARNER, LEARNER, EXPERT]


def test_thrifty_gate_switches_and_hands_back():
    rng = np.random.default_rng(0)
    gate = ThriftyGate(novelty_threshold=0.5, risk_threshold=0.5)
    gate.begin_episode(EpisodeContext(2, 10))
    assert gate.choose(StepView(2, 0, 0, 0.1, 1, 1, novelty=0.1, risk=0.1), rng)[0] == LEARNER
    assert gate.choose(StepView(2, 1, 0, 0.9, 1, 2, novelty=0.9, risk=0.1), rng)[0] == EXPERT
    assert gate.choose(StepView(2, 2, 0, 0.1, 1, 2, novelty=0.1, risk=0.1), rng)[0] == EXPERT  # still differ
    assert gate.choose(StepView(2, 3, 0, 0.1, 1, 1, novelty=0.1, risk=0.1), rng)[0] == LEARNER  # agree: hand back


class _Critic:
    """A stand-in ThriftyDAgger learner: risk read from the frame's first pixel (0..255 -> 0..1)."""

    def __init__(self):
        self.novelty_threshold, self.risk_threshold, self.calls = 0.5, 0.5, 0

    def risk(self, obs):
        self.calls += 1
        return float(obs[0, 0, 0]) / 255.0


def test_thrifty_gate_reads_its_critic_each_episode():
    rng, critic = np.random.default_rng(0), _Critic()
    gate = ThriftyGate(critic=critic)

    def frame(risk):
        return np.full((2, 2, 3), int(risk * 255), np.uint8)

    gate.begin_episode(EpisodeContext(2, 10))
    assert (gate.novelty_threshold, gate.risk_threshold) == (0.5, 0.5)
    assert gate.choose(StepView(2, 0, 0, 0.1, 1, 1, novelty=0.1, obs=frame(0.2)), rng)[0] == LEARNER
    assert gate.choose(StepView(2, 1, 0, 0.1, 1, 1, novelty=0.1, obs=frame(0.9)), rng)[0] == EXPERT  # risky
    assert gate.choose(StepView(2, 2, 0, 0.1, 1, 1, novelty=0.1, obs=frame(0.1)), rng)[0] == LEARNER  # hand back
    critic.risk_threshold = 0.05  # refit after the episode: read at the next episode's start
    assert gate.risk_threshold == 0.5
    gate.begin_episode(EpisodeContext(3, 10))
    assert gate.risk_threshold == 0.05
    assert gate.choose(StepView(3, 0, 0, 0.1, 1, 1, novelty=0.1, obs=frame(0.1)), rng)[0] == EXPERT
    calls = critic.calls  # no learner action: no risk asked, none assumed
    gate.begin_episode(EpisodeContext(4, 10))
    assert gate.choose(StepView(4, 0, 0, 0.1, 1, None, novelty=0.1, obs=frame(0.9)), rng)[0] == LEARNER
    assert critic.calls == calls


def test_action_distance():
    assert action_distance(3, 3) == 0.0 and action_distance(3, 4) == 1.0
    assert action_distance(np.array([0.0, 1.0]), np.array([3.0, 5.0])) == pytest.approx(5.0)
    assert action_distance(None, 1) == math.inf


def _v(t=0, u_expert=1.0, u_learner=0.5, i=2):
    return StepView(i=i, t=t, u_expert=u_expert, u_learner=u_learner)


def test_sampling_strategies():
    rng = np.random.default_rng(0)
    assert FullHorizon().control(_v(), LEARNER, 0.3, rng) == LEARNER
    sw = RandomSwitch()
    sw.begin_episode(EpisodeContext(1, 10), rng)
    assert [sw.control(_v(t), LEARNER, 1.0, rng) for t in range(10)] == [EXPERT] * 10
    ctx = EpisodeContext(2, 10)
    sw.begin_episode(ctx, rng)
    ts = ctx.switch_time
    got = [sw.control(_v(t), LEARNER, 1.0, rng) for t in range(10)]
    assert got == [LEARNER] * ts + [EXPLORER] + [EXPERT] * (9 - ts)
    rs = RationalSampling("code", expert_threshold=1.0)
    rs.begin_episode(EpisodeContext(2, 10), rng)
    assert all(rs.control(_v(u_expert=5.0), LEARNER, 1.0, rng) == LEARNER for _ in range(50))  # p_choice 1: kept
    # p_choice 0: E' = expert w.p. alpha_T; alpha(inf) = 0 -> always the explorer
    assert all(rs.control(_v(u_expert=math.inf), LEARNER, 0.0, rng) == EXPLORER for _ in range(50))
    assert all(rs.control(_v(u_expert=0.0), LEARNER, 0.0, rng) == EXPERT for _ in range(50))


def test_code_sampling_never_explores_with_the_0_inf_expert():
    """The departure the thesis configuration fixes: with U_T in {0, inf} the code variant's
    explorer never acts (U_T = inf makes the learner's choice certain, U_T = 0 makes E' the expert)."""
    rng = np.random.default_rng(0)
    mix, rs = RationalMixing(1.0, 1.0), RationalSampling("code", expert_threshold=1.0)
    rs.begin_episode(EpisodeContext(2, 10), rng)
    for u_t in (0.0, math.inf):
        for u_l in (0.0, 0.3, 3.0):
            v = _v(u_expert=u_t, u_learner=u_l)
            for _ in range(200):
                chosen, p = mix.choose(v, rng)
                assert rs.control(v, chosen, p, rng) != EXPLORER


def test_thesis_rational_sampling_eq_19_to_21():
    """pi_RS = a pi_i + (1 - a) E', a = tanh(30 U_L); E' = alpha_T expert + (1 - alpha_T) E."""
    rng = np.random.default_rng(2)
    rs = RationalSampling("thesis", scale=30.0)
    rs.begin_episode(EpisodeContext(1, 10), rng)
    assert all(rs.control(_v(u_expert=math.inf, u_learner=0.0, i=1), EXPERT, 1.0, rng) == EXPERT
               for _ in range(50))  # episode 1: the demonstration
    rs.begin_episode(EpisodeContext(2, 10), rng)
    # a certain learner (U_L = 0): a = 0, always E'; the expert not intervening (inf): the explorer acts
    assert all(rs.control(_v(u_expert=math.inf, u_learner=0.0), LEARNER, 1.0, rng) == EXPLORER for _ in range(50))
    # ... the expert intervening (U_T = 0): alpha_T = 1, E' is the expert
    assert all(rs.control(_v(u_expert=0.0, u_learner=0.0), LEARNER, 1.0, rng) == EXPERT for _ in range(50))
    # a very uncertain learner: a = tanh(30 * 10) = 1, the mixture's choice is kept
    assert all(rs.control(_v(u_expert=math.inf, u_learner=10.0), LEARNER, 0.5, rng) == LEARNER for _ in range(50))
    # in between: the mixture's choice with probability tanh(30 U_L), whatever its own probability
    u_l = 0.02
    a = math.tanh(30 * u_l)
    n = 4000
    kept = sum(rs.control(_v(u_expert=math.inf, u_learner=u_l), LEARNER, 0.99, rng) == LEARNER for _ in range(n))
    assert abs(kept / n - a) < 6 * math.sqrt(a * (1 - a) / n)
    # UPMS-NE: E = the learner, so no random explorer ever acts
    ne = RationalSampling("thesis", scale=30.0, explorer=LEARNER)
    ne.begin_episode(EpisodeContext(2, 10), rng)
    got = {ne.control(_v(u_expert=math.inf, u_learner=u_l), EXPERT, 1.0, rng) for _ in range(500)}
    assert got == {EXPERT, LEARNER}
    with pytest.raises(ValueError, match="scale"):
        RationalSampling("thesis")


def test_thesis_mixing_scales_the_uncertainty_by_30():
    mix = RationalMixing(scale=30.0)
    assert mix.c_expert == mix.c_learner == 30.0
    # the 0/inf expert: intervening (0) vs a learner at sigma^2 = 0.1, where 1 - tanh(3) ~ 0.005
    p = rational_mixing(0.0, 0.1, 30.0, 30.0)
    assert p == pytest.approx(1.0 / (1.0 + 1.0 - math.tanh(3.0)))
    assert rational_mixing(math.inf, 0.1, 30.0, 30.0) == 0.0  # not intervening: the learner acts
