"""Experts (scripted oracle, human with scripted key events) and the crossing environment."""

import math

import numpy as np
import pytest

from crossing_assist.actions import UNKNOWN, get_space
from crossing_assist.iil.envs import make_env
from crossing_assist.iil.envs.crossing import CrossingConfig, CrossingEnv, synthetic_frame
from crossing_assist.iil.experts import HumanExpert, KeyMap, OracleExpert, ScriptedEvents, risk_to_uncertainty


def test_risk_to_uncertainty_is_continuous_and_spans_zero_to_infinity():
    assert risk_to_uncertainty(1.0) == 0.0
    assert risk_to_uncertainty(0.0) == math.inf
    us = [risk_to_uncertainty(r) for r in np.linspace(0.05, 1.0, 20)]
    assert all(a > b for a, b in zip(us, us[1:]))
    assert risk_to_uncertainty(0.5, scale=2.0) == pytest.approx(2.0)


def test_human_expert_follows_scripted_keys():
    events = ScriptedEvents([[("down", "7")], [], [("down", "space")], [("up", "space")], [("up", "7")], [],
                             [("down", "x")]])
    human = HumanExpert(events, KeyMap.crossing())
    got = [human.act(None) for _ in range(7)]
    assert got[0] == (7, 0.0) and got[1] == (7, 0.0)          # held key keeps acting
    assert got[2] == (UNKNOWN, 0.0)                            # the latest key wins: space = stop
    assert got[3] == (7, 0.0)                                  # released: back to the held 7
    assert got[4][0] is None and got[4][1] == math.inf         # nothing held: no action
    assert got[6][0] is None                                   # unmapped keys are ignored
    assert KeyMap.crossing().keys["="] == 12 and KeyMap.crossing().keys["1"] == 1


def test_gamepad_axis_gives_a_continuous_confidence():
    human = HumanExpert(ScriptedEvents([[("axis", 0.25)], [("axis", -1.0)], [("axis", 0.0)]]),
                        axis_to_action=lambda v: 1 if v < 0 else 2)
    a1, u1 = human.act(None)
    a2, u2 = human.act(None)
    a3, u3 = human.act(None)
    assert (a1, a2, a3) == (2, 1, None)
    assert u1 == pytest.approx(3.0) and u2 == 0.0 and u3 == math.inf


def test_crossing_expert_is_the_true_bin_and_frames_follow_the_heading():
    env = CrossingEnv(CrossingConfig(photos=None))
    env.reset(seed=3)
    env.y, env.s, env.phi = 0.0, 0.0, 0.0
    assert env.true_bin() in (6, 7)                     # straight ahead: the central strips
    env.phi = -30.0                                     # facing left: the goal is to the right
    b, risk = env.oracle()
    assert b == get_space(13).bin_to_action(env.true_bin()) and b >= 9 and 0 < risk <= 1
    env.phi = 80.0                                      # out of view on the left
    assert env.true_bin() == UNKNOWN and env.oracle()[0] == 1
    left, right = synthetic_frame(-30, 64, 48), synthetic_frame(30, 64, 48)
    cols = lambda img: np.nonzero(img[20:30].min(-1).max(0) > 200)[0].mean()  # noqa: E731
    assert cols(left) < 32 < cols(right)


def test_crossing_out_of_bounds_and_expert_keeps_the_walker_in():
    env = make_env("crossing-synthetic")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (48, 64, 3) and obs.dtype == np.uint8
    env.y = 1.45
    env.phi = 60.0
    _, r, term, _, info = env.step(12)
    assert info["out_of_bounds"] and r == -1000.0 and term
    expert = OracleExpert(env)
    oob = 0
    for k in range(3):
        obs, _ = env.reset(seed=k)
        for _ in range(60):
            a, u = expert.act(obs)
            assert u >= 0
            obs, r, term, _, info = env.step(a)
            oob += info["out_of_bounds"]
            if term:
                break
    assert oob == 0


def test_crossing_with_real_ptl_photos(ptl_dir):
    from crossing_assist.actions import x_to_bin, x_to_heading

    env = CrossingEnv(CrossingConfig(photos=str(ptl_dir), n_photos=4))
    assert env.source == "ptl"
    env.reset(seed=1)
    h0 = x_to_heading(env.photos[env.photo][1])
    env.y, env.s, env.phi = 0.0, 0.0, -h0            # facing so that the far end is where the photo has it
    straight = env._obs()
    assert straight.shape == (48, 64, 3) and straight[:, -4:].mean() > 10  # the photo itself, no border
    env.phi = -h0 + 30.0                              # turned 30 degrees right: the unseen right is filled
    turned = env._obs()
    assert turned[:, -4:].mean() > 10 and not (turned == 0).all(axis=2).any()
    assert env.true_bin() < x_to_bin(env.photos[env.photo][1])  # the far end moved left


def _fake_ptl(root, n=6, seed=0):
    """A PTL-shaped folder of random-texture photos (no pixel is black), read by
    ``data_tools.ptl.read_ptl_labels`` like the real one."""
    import cv2

    from crossing_assist.actions import x_to_bin

    rng = np.random.default_rng(seed)
    (root / "images").mkdir(parents=True)
    lines = ["image,split,photographer,far_x,bin12"]
    for k in range(n):
        img = rng.integers(30, 226, size=(96, 128, 3), dtype=np.uint8)
        cv2.imwrite(str(root / "images" / f"p{k}.png"), img)
        far_x = round(float(rng.uniform(0.2, 0.8)), 3)
        lines.append(f"images/p{k}.png,train,p{k},{far_x},{x_to_bin(far_x)}")
    (root / "labels.csv").write_text("\n".join(lines) + "\n")
    return root


def _nearest_neighbour_accuracy(x, y):
    """1-NN trained on the even samples, scored on the odd ones; and the best constant's score
    there (the majority class of the scored samples)."""
    tr, te = slice(0, None, 2), slice(1, None, 2)
    pred = y[tr][np.argmin(((x[te][:, None] - x[tr][None]) ** 2).sum(-1), axis=1)]
    return float((pred == y[te]).mean()), float(np.bincount(y[te]).max() / len(y[te]))


def test_the_border_of_a_turned_frame_does_not_tell_the_label(tmp_path):
    """A classifier that sees only the mask of black (unfilled) pixels of the frames cannot beat
    the majority class; with the old black border (``augment.yaw``) the same classifier could."""
    from crossing_assist.actions import x_to_heading
    from crossing_assist.data_tools.augment import yaw

    env = CrossingEnv(CrossingConfig(photos=str(_fake_ptl(tmp_path / "ptl", n=2)), n_photos=2))
    rng = np.random.default_rng(0)
    masks_new, masks_old, labels = [], [], []
    for k in range(300):
        env.reset(seed=k)
        env.phi += float(rng.uniform(-40, 40))  # spread the bearings over the view and beyond
        labels.append(env.true_bin())
        masks_new.append((env._obs() == 0).all(axis=2).mean(0))        # per-column black fraction
        img, far_x = env.photos[env.photo]
        psi = float(np.clip(x_to_heading(far_x) - env.bearing(), -80, 80))
        old = yaw(img, far_x, 1, psi)[0]
        masks_old.append((old == 0).all(axis=2).mean(0))
    y = np.array(labels)
    acc_new, major = _nearest_neighbour_accuracy(np.array(masks_new), y)
    acc_old, _ = _nearest_neighbour_accuracy(np.array(masks_old), y)
    assert acc_old > major + 0.1           # the test has power: the black border leaked the label
    assert acc_new <= major + 1e-9         # filled: nothing to learn from the mask


def test_binary_expert_is_certain_only_above_its_risk():
    env = CrossingEnv(CrossingConfig(photos=None))
    env.reset(seed=0)
    binary = OracleExpert(env, binary_risk=0.5)
    env.y, env.s, env.phi = 0.0, 0.0, 0.0
    assert binary.act(None) == (env.oracle()[0], math.inf)  # safe: the thesis's expert does not care
    env.y = 1.2                                          # 80 % of the half width: it intervenes, certain
    action, u = binary.act(None)
    assert action == env.oracle()[0] and u == 0.0
