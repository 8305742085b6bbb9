"""A tiny untrained policy for export tests: squeezenet 1.1 (no weights) and a spatial head whose
logits are spread (random-init squeezenet features are small), on a 32 x 32 canvas."""

import torch

from crossing_assist.models.backbones import create_backbone
from crossing_assist.models.heads import create_head
from crossing_assist.models.policy import Policy, policy_config


def tiny_policy(n_actions: int) -> Policy:
    torch.manual_seed(0)
    backbone = create_backbone("squeezenet1_1", weights="none")
    head = create_head("spatial", backbone.num_features, n_actions, p=0.5)
    with torch.no_grad():
        for prm in head.parameters():
            prm.mul_(8.0)
    return Policy(backbone, head, policy_config(backbone, "spatial", n_actions, input_size=(32, 32), data="tiny",
                                                counts={"train": 0}))
