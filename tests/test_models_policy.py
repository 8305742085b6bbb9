"""PolicyConfig: the frozen, typed config of a policy; plain JSON in checkpoints, old ones still load."""

import dataclasses
import json

import pytest
import torch

from crossing_assist.geometry import PAD_RGB
from crossing_assist.models.backbones import create_backbone
from crossing_assist.models.checkpoint import FORMAT, VERSION, CheckpointError, load_checkpoint, load_policy, save_checkpoint
from crossing_assist.models.policy import CONFIG_KEYS, Policy, PolicyConfig, policy_config

# a checkpoint config as written before PolicyConfig existed and before the geometry contract
# (no fit, pad_rgb, frozen_blocks, counts, majority_action)
OLD = {"backbone": "mobilenet_v3_small", "weights_source": "random init", "licence": "n/a", "head": "spatial",
       "n_actions": 13, "names": ["unknown"] + [str(i) for i in range(1, 13)], "p": 0.5, "input_size": [32, 32],
       "mean": [0.485, 0.456, 0.406], "std": [0.229, 0.224, 0.225], "fov_deg": 67.0, "data": "old/data"}


def _full() -> PolicyConfig:
    return PolicyConfig(backbone="mobilenet_v3_small", weights_source="imagenet", licence="BSD-3-Clause",
                        head="spatial", n_actions=13, p=0.3, input_size=(168, 224), mean=(0.5, 0.5, 0.5),
                        std=(0.25, 0.25, 0.25), fov_deg=67.0, frozen_blocks=9, data="data/x", fit="letterbox",
                        pad_rgb=(1, 2, 3), counts={"train_split": 8, "val": 2}, majority_action=6,
                        extra={"note": "kept"})


def test_round_trip_is_plain_json_and_exact():
    c = _full()
    d = c.to_dict()
    assert json.loads(json.dumps(d)) == d                       # plain JSON, nothing to pickle
    assert "extra" not in d and d["note"] == "kept"              # extra keys sit at the top level, as read
    assert list(d)[:11] == ["backbone", "weights_source", "licence", "head", "n_actions", "names", "p",
                            "input_size", "mean", "std", "fov_deg"]   # the key order checkpoints always had
    assert PolicyConfig.from_dict(d) == c
    assert PolicyConfig.from_dict(json.loads(json.dumps(d))) == c
    assert c.input_size == (168, 224) and c.names[1:] == tuple(str(i) for i in range(1, 13))


def test_policy_config_fills_the_backbone_facts():
    bb = create_backbone("mobilenet_v3_small", weights="none")
    c = policy_config(bb, "spatial", 8, input_size=(32, 48), fit="letterbox", data="d")
    assert isinstance(c, PolicyConfig)
    assert (c.backbone, c.n_actions, c.input_size, c.mean, c.std) == (bb.facts.name, 8, (32, 48), tuple(bb.facts.mean),
                                                                      tuple(bb.facts.std))
    assert len(c.names) == 8 and c.fit == "letterbox" and c.data == "d"
    with pytest.raises(TypeError):
        policy_config(bb, "spatial", 8, not_a_field=1)


def test_old_dict_loads_with_the_defaults_it_was_trained_with():
    c = PolicyConfig.from_dict({**OLD, "future_key": [1, 2]})
    assert c.fit == "stretch" and c.pad_rgb == PAD_RGB
    assert c.frozen_blocks is None and c.counts == {} and c.majority_action is None
    assert c.extra == {"future_key": [1, 2]} and c.to_dict()["future_key"] == [1, 2]
    without_names = {k: v for k, v in OLD.items() if k != "names"}
    assert PolicyConfig.from_dict(without_names).names == c.names


def test_old_checkpoint_loads_through_load_policy(tmp_path):
    torch.manual_seed(0)
    policy = Policy.from_config(OLD)                             # a dict is accepted via from_dict
    path = tmp_path / "old.pt"
    torch.save({"format": FORMAT, "version": VERSION, "state_dict": policy.state_dict(), "config": dict(OLD),
                "metrics": {}, "epoch": 1}, path)
    got = load_policy(path)
    assert isinstance(got.config, PolicyConfig) and got.config.fit == "stretch" and got.config.data == "old/data"
    assert got.backbone.facts.weights_source == "random init"
    save_checkpoint(tmp_path / "new.pt", got)                    # written back as the plain dict
    written = load_checkpoint(tmp_path / "new.pt")["config"]
    assert written == got.config.to_dict() and {k: written[k] for k in OLD} == OLD


@pytest.mark.parametrize("key, value", [("n_actions", "13"), ("n_actions", 5), ("p", True), ("p", 1.0),
                                        ("input_size", [32]), ("input_size", "32x32"), ("mean", [0.5, "a", 0.5]),
                                        ("fit", "crop"), ("pad_rgb", [1, 2]), ("backbone", 3),
                                        ("frozen_blocks", 2.5), ("counts", [1, 2]), ("majority_action", "6")])
def test_a_wrong_type_or_value_is_one_line_value_error(key, value):
    with pytest.raises(ValueError, match=r"^(Invalid policy config|Unknown action space)[^\n]*$"):
        PolicyConfig.from_dict({**OLD, key: value})


def test_missing_required_key_is_named():
    for key in CONFIG_KEYS:
        with pytest.raises(ValueError, match=f"Invalid policy config: missing {key}$"):
            PolicyConfig.from_dict({k: v for k, v in OLD.items() if k != key})


def test_bad_config_in_a_checkpoint_is_a_checkpoint_error(tmp_path):
    policy = Policy.from_config(OLD)
    path = tmp_path / "bad.pt"
    torch.save({"format": FORMAT, "version": VERSION, "state_dict": policy.state_dict(),
                "config": {**OLD, "input_size": "32x32"}, "metrics": {}, "epoch": 1}, path)
    with pytest.raises(CheckpointError, match="does not fit its config: Invalid policy config: input_size"):
        load_policy(path)


def test_config_is_frozen_and_replace_makes_a_checked_copy():
    c = _full()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.fit = "stretch"
    d = dataclasses.replace(c, majority_action=2)
    assert d.majority_action == 2 and c.majority_action == 6
    with pytest.raises(ValueError, match="Invalid policy config: extra"):
        dataclasses.replace(c, extra={"fit": "stretch"})         # an extra key may not shadow a field
