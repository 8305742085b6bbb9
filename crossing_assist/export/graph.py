"""The bundle's ONNX graph: raw uint8 frames in, MC-dropout summaries out, in ONE pass.

Layout of :class:`BundleGraph` (docs/contracts.md section 3):

    frames uint8 [N, H, W, 3] RGB (N, H, W dynamic)
      -> float, /255, NCHW, fitted to the canvas ``size``: ``letterbox`` (bilinear antialiased
         resize to the box of :func:`crossing_assist.geometry.letterbox_box`, centred, padded
         with ``pad_rgb``) or ``stretch``; (x - mean) / std; the content window (x0, x1)
      -> policy(x, samples=T, mc=p > 0, window): the head reads its 12 strips inside the window: the backbone and the head's deterministic part run
         once; the T dropout samples are folded into the batch inside the head with explicit
         ``rand_like(x) >= p`` masks (exported as RandomUniformLike, which onnxruntime's graph
         optimiser keeps, unlike Dropout nodes)
      -> (``mirror``: the same for the frames flipped left-right, their actions mapped back
         (strip k -> 13 - k), so T samples of each: logits [2T, N, A])
      -> logits [T, N, A] / temperature -> per-sample softmax
      -> probs [N, A] (mean), entropy [N], mutual_info [N], variance [N, A], votes [N, A]

:func:`crossing_assist.models.mc.mc_summaries` is that tail (the one copy, shared with the IIL
learners), also used for the PyTorch reference.
"""

from __future__ import annotations

import copy
import warnings
from dataclasses import dataclass
from typing import Any, Mapping

import torch
import torch.nn.functional as F
from torch import nn

from crossing_assist.actions import get_space
from crossing_assist.bundle import INPUT_NAME, OUTPUT_NAMES, graph_metadata
from crossing_assist.geometry import FITS, PAD_RGB
from crossing_assist.models.mc import mc_summaries

OPSET = 18
MAX_SIDE = 8192


@dataclass(frozen=True)
class GraphSpec:
    """What the graph bakes in. ``size`` = (H, W) the policy sees; ``mean``/``std`` per RGB
    channel on the 0..1 scale; ``samples`` = T; ``p`` = drop probability of the sampled layers
    (0 = deterministic); ``temperature`` divides the logits (> 0); ``mirror``: mirror
    test-time augmentation (the frame and its mirror image, 2T samples summarised together)."""

    size: tuple[int, int]
    mean: tuple[float, float, float]
    std: tuple[float, float, float]
    samples: int = 16
    p: float = 0.5
    temperature: float = 1.0
    fit: str = "letterbox"
    pad_rgb: tuple[int, int, int] = PAD_RGB
    mirror: bool = False

    def __post_init__(self) -> None:
        if self.fit not in FITS:
            raise ValueError(f"Unknown fit: {self.fit!r}; valid: {', '.join(FITS)}")
        if self.samples < 1:
            raise ValueError(f"Invalid samples: {self.samples}; valid: >= 1")
        if not 0.0 <= self.p < 1.0:
            raise ValueError(f"Invalid p: {self.p}; valid: 0 <= p < 1")
        if not self.temperature > 0:
            raise ValueError(f"Invalid temperature: {self.temperature}; valid: > 0")


class BundleGraph(nn.Module):
    """Wraps a policy (``forward(x, samples, mc) -> logits [T, N, A]``, ``head.p`` settable)
    into the bundle's graph. The policy is deep-copied, put in eval mode (BatchNorm uses its
    running statistics) and its head's drop probability set to ``spec.p``."""

    def __init__(self, policy: nn.Module, spec: GraphSpec):
        super().__init__()
        self.spec = spec
        self.policy = copy.deepcopy(policy).eval()
        self.policy.head.p = spec.p
        for prm in self.policy.parameters():
            prm.requires_grad_(False)
        self.register_buffer("mean", torch.tensor(spec.mean, dtype=torch.float32).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(spec.std, dtype=torch.float32).view(1, 3, 1, 1))
        self.register_buffer("pad", torch.tensor(spec.pad_rgb, dtype=torch.float32).view(1, 3, 1, 1) / 255.0)
        if spec.mirror:   # action a of the mirrored frame is action mirrored[a] of the frame
            space = get_space(self.policy.n_actions)
            self.register_buffer("mirrored", torch.tensor([space.mirror_action(a) for a in range(space.n)]))

    def preprocess(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """uint8 [N, H, W, 3] RGB -> (normalised float [N, 3, h, w] at ``spec.size``, the
        content window [N, 2] as fractions of the canvas width)."""
        x = frames.permute(0, 3, 1, 2).to(torch.float32) / 255.0
        n, _, h, w = x.shape
        ch, cw = self.spec.size
        if self.spec.fit == "stretch":
            x = F.interpolate(x, size=(ch, cw), mode="bilinear", align_corners=False, antialias=True)
            window = torch.tensor([0.0, 1.0]).expand(n, 2)
            return (x - self.mean) / self.std, window
        # crossing_assist.geometry.letterbox_box, in symbolic integers (exported as shape arithmetic)
        new_w = torch.sym_max(1, torch.sym_min(cw, (w * ch * 2 + h) // (2 * h)))
        new_h = torch.sym_max(1, torch.sym_min(ch, (h * cw * 2 + w) // (2 * w)))
        top, left = (ch - new_h) // 2, (cw - new_w) // 2
        x = F.interpolate(x, size=(new_h, new_w), mode="bilinear", align_corners=False, antialias=True)
        x = F.pad(x - self.pad, (left, cw - new_w - left, top, ch - new_h - top), value=0.0) + self.pad
        edges = torch.stack([torch.scalar_tensor(left), torch.scalar_tensor(left + new_w)]).to(torch.float32)
        window = (edges / cw).view(1, 2).expand(n, 2)
        return (x - self.mean) / self.std, window

    def logits(self, frames: torch.Tensor) -> torch.Tensor:
        """Raw (untempered) logits [T, N, A] of the T samples."""
        x, window = self.preprocess(frames)
        if not self.spec.mirror:
            return self.policy(x, samples=self.spec.samples, mc=self.spec.p > 0, window=window)
        # the letterbox is centred, so the mirrored frame's window is the mirror of the window
        n = x.shape[0]
        both = self.policy(torch.cat([x, x.flip(-1)]), samples=self.spec.samples, mc=self.spec.p > 0,
                           window=torch.cat([window, 1.0 - window.flip(-1)]))
        return torch.cat([both[:, :n], both[:, n:].index_select(-1, self.mirrored)])

    def forward(self, frames: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return mc_summaries(self.logits(frames), self.spec.temperature)


def export_graph(policy: nn.Module, spec: GraphSpec, *, example_hw: tuple[int, int] | None = None) -> Any:
    """Export ``BundleGraph(policy, spec)`` to an in-memory ``onnx.ModelProto`` (weights embedded,
    no external data), with N, H and W dynamic."""
    import onnx  # noqa: F401  (fail early with a clear ImportError when missing)

    graph = BundleGraph(policy, spec).eval()
    h, w = example_hw or (spec.size[0] + 8, spec.size[1] + 12)
    example = torch.zeros(2, h, w, 3, dtype=torch.uint8)
    dims = {0: torch.export.Dim("N", min=1, max=4096),
            1: torch.export.Dim("H", min=8, max=MAX_SIDE), 2: torch.export.Dim("W", min=8, max=MAX_SIDE)}
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        program = torch.onnx.export(
            graph, (example,), input_names=[INPUT_NAME], output_names=list(OUTPUT_NAMES),
            dynamic_shapes={"frames": dims}, dynamo=True, external_data=False,
            opset_version=OPSET, verbose=False, optimize=True,
        )
    model = program.model_proto
    ops = {n.op_type for n in model.graph.node}
    if spec.p > 0 and spec.samples > 1 and "RandomUniformLike" not in ops and "RandomUniform" not in ops:
        raise RuntimeError("the exported graph has no random op: the policy's head does not sample "
                           "rand_like dropout masks when mc=True; MC dropout would silently vanish")
    return model


def set_metadata(model: Any, meta: Mapping[str, Any]) -> None:
    """Store the bundle facts in ``model.metadata_props`` (``bundle_json``, ``schema_version``)."""
    props = graph_metadata(meta)
    keep = [p for p in model.metadata_props if p.key not in props]
    del model.metadata_props[:]
    for p in keep:
        model.metadata_props.append(p)
    for key, value in props.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value


def model_bytes(model: Any) -> bytes:
    """Serialise a ModelProto to one self-contained byte string (refuses > 2 GB / external data)."""
    for init in model.graph.initializer:
        if init.data_location == 1:  # onnx.TensorProto.EXTERNAL
            raise RuntimeError(f"initializer {init.name} uses external data; the bundle must be one file")
    return model.SerializeToString()
