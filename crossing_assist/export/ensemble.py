"""Several bundles' graphs as one: an ensemble bundle (``crossing-export ensemble``).

Models trained alike but from different seeds are wrong on different frames; averaged, their
probabilities are less often confidently wrong on photographers none of them trained on
(docs/models.md, "The default is an ensemble of two seeds"). :func:`merge_graphs` puts the
members' graphs side by side behind the one ``frames`` input and pools their MC samples: each
member's T (or 2T with mirror) samples count alike, so the five outputs are exactly those of one
graph summarising all of the members' samples (:func:`crossing_assist.models.mc.mc_summaries`):

    probs       = mean_m probs_m
    entropy     = H(probs)
    mutual_info = max(0, H(probs) - mean_m (entropy_m - mutual_info_m))
    variance    = max(0, mean_m (variance_m + probs_m^2) - probs^2)
    votes       = mean_m votes_m

The consumer sees the same inputs and outputs as a one-model bundle (docs/contracts.md section 3):
the runtime and the phone app run it unchanged. What the members compute alike runs once
(:func:`share_alike`): members fine-tuned from one backbone with its first blocks frozen share those
blocks and the frame's fitting, which in the default (EfficientNet-Lite0, ``--unfreeze 8``) is 432
of its three members' 1,200 nodes and a third of its time a frame; the outputs are unchanged bit
for bit (each member keeps its own dropout masks). The
thresholds do not carry over from the members (the averaged probabilities are smoother than any
member's), so :func:`ensemble_bundle` fits the conformal and gate thresholds again on labelled
frames, through the merged graph, as ``crossing-export`` does for one model.
"""

from __future__ import annotations

import json
import shlex
import sys
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from crossing_assist.bundle import (
    INPUT_NAME,
    OUTPUT_NAMES,
    Bundle,
    BundleError,
    check_replaceable,
    read_bundle,
    write_bundle,
)
from crossing_assist.export import calibrate as cal
from crossing_assist.export.exporter import (
    EXPORT_MEASURES,
    MIN_CALIB_CROSSINGS,
    ExportError,
    _fit_and_measure,
    check_calib_size,
    load_labelled,
)
from crossing_assist.export.graph import model_bytes, set_metadata

#: The bundle.json fields the members must share: the graph's input, what its outputs mean, and
#: how a consumer fits a frame to it.
SHARED = ("actions", "fov_deg", "input", "geometry")


@dataclass(frozen=True)
class EnsembleConfig:
    """Options of ``crossing-export ensemble`` (the calibration fields as :class:`ExportConfig`'s)."""

    members: tuple[str, ...]
    out: str
    calib_data: str
    calib_split: str = "val"
    coverage: float = 0.9
    measure: str = "far_mass"
    gate_scale: float = 1.0
    gate_scale_portrait: float | None = None
    batch: int = 32
    seed: int = 0
    progress: bool = True
    force: bool = False
    min_calib: int = MIN_CALIB_CROSSINGS

    def __post_init__(self) -> None:
        if self.min_calib < 1:
            raise ExportError(f"Invalid --min-calib {self.min_calib}; valid: >= 1")
        if len(self.members) < 2:
            raise ExportError(f"Invalid members: {len(self.members)} bundle(s); an ensemble needs at least 2")
        if self.measure not in EXPORT_MEASURES:
            raise ExportError(f"Invalid --measure {self.measure!r}; valid: {', '.join(EXPORT_MEASURES)}")
        if not 0.0 < self.coverage < 1.0:
            raise ExportError(f"Invalid --coverage {self.coverage}; valid: 0 < coverage < 1")
        for name in ("gate_scale", "gate_scale_portrait"):
            v = getattr(self, name)
            if v is not None and not 0.05 <= v <= 20:
                raise ExportError(f"Invalid --{name.replace('_', '-')} {v}; valid: 0.05..20")


def merged_members(model: Any) -> int:
    """How many members a graph pools: k for one :func:`merge_graphs` made (``ensemble_of_k``), else 1."""
    name = model.graph.name
    return int(name.removeprefix("ensemble_of_")) if name.startswith("ensemble_of_") else 1


def _prune(graph: Any, wanted: set[str]) -> None:
    """Keep only the nodes of ``graph`` that the tensors ``wanted`` need (in place)."""
    needed, keep = set(wanted), []
    for node in reversed(graph.node):
        if needed.intersection(node.output):
            keep.append(type(node).FromString(node.SerializeToString()))
            needed.update(node.input)
    del graph.node[:]
    graph.node.extend(reversed(keep))


def merge_graphs(models: Sequence[Any], share: bool = True) -> Any:
    """One ``onnx.ModelProto`` running every model of ``models`` on the shared ``frames`` input
    and pooling their summaries (module docstring), what they compute alike run once
    (:func:`share_alike`; ``share=False``: side by side, as merged before 2026-12-07). A model
    that is itself a merged ensemble (:func:`merged_members`) counts as its members: its pooling
    is dropped and theirs pooled with the others', as if they had been merged one by one (so a
    member can be added to a shipped ensemble whose members' bundles are gone). The models must
    share their opsets."""
    import onnx
    from onnx import TensorProto, compose, helper, numpy_helper

    if len(models) < 2:
        raise ValueError(f"an ensemble needs at least 2 models, got {len(models)}")
    opsets = {(o.domain, o.version) for o in models[0].opset_import}
    for i, m in enumerate(models[1:], 1):
        if {(o.domain, o.version) for o in m.opset_import} != opsets:
            raise ExportError(f"member {i + 1}'s graph uses other opsets than member 1's "
                              f"({sorted(o.version for o in m.opset_import)} vs {sorted(v for _, v in opsets)}); "
                              "export them with one crossing_assist version")
    graphs, heads = [], []   # heads: each member's output prefix in the merged graph
    for i, m in enumerate(models):
        g = compose.add_prefix(m, f"m{i}/", rename_inputs=False).graph
        if (k_i := merged_members(m)) > 1:   # an ensemble: its members' own outputs, not its pooling
            members = [f"m{i}/m{j}/" for j in range(k_i)]
            _prune(g, {head + name for head in members for name in OUTPUT_NAMES})
            heads += members
        else:
            heads.append(f"m{i}/")
        graphs.append(g)
    k = len(heads)
    n = helper.make_node
    out = lambda i, name: heads[i] + name  # noqa: E731
    const = lambda name, value, dtype=np.float32: n(  # noqa: E731
        "Constant", [], [name], value=numpy_helper.from_array(np.asarray(value, dtype), name + "_v"))
    tail = [
        n("Mean", [out(i, "probs") for i in range(k)], ["probs"]),
        n("Mean", [out(i, "votes") for i in range(k)], ["votes"]),
        const("ens/tiny", 1e-30), const("ens/zero", 0.0), const("ens/last", [-1], np.int64),
        n("Max", ["probs", "ens/tiny"], ["ens/probs_floor"]),
        n("Log", ["ens/probs_floor"], ["ens/log_probs"]),
        n("Mul", ["probs", "ens/log_probs"], ["ens/plogp"]),
        n("ReduceSum", ["ens/plogp", "ens/last"], ["ens/neg_entropy"], keepdims=0),
        n("Neg", ["ens/neg_entropy"], ["entropy"]),
    ]
    for i in range(k):   # each member's mean per-sample entropy, and its samples' second moment
        tail += [n("Sub", [out(i, "entropy"), out(i, "mutual_info")], [f"ens/expected{i}"]),
                 n("Mul", [out(i, "probs"), out(i, "probs")], [f"ens/p2_{i}"]),
                 n("Add", [out(i, "variance"), f"ens/p2_{i}"], [f"ens/moment{i}"])]
    tail += [
        n("Mean", [f"ens/expected{i}" for i in range(k)], ["ens/expected"]),
        n("Sub", ["entropy", "ens/expected"], ["ens/mi_raw"]),
        n("Max", ["ens/mi_raw", "ens/zero"], ["mutual_info"]),
        n("Mean", [f"ens/moment{i}" for i in range(k)], ["ens/moment"]),
        n("Mul", ["probs", "probs"], ["ens/probs2"]),
        n("Sub", ["ens/moment", "ens/probs2"], ["ens/var_raw"]),
        n("Max", ["ens/var_raw", "ens/zero"], ["variance"]),
    ]
    a = next(o for o in models[0].graph.output if o.name == "probs").type.tensor_type.shape.dim[1].dim_value or "A"
    f = TensorProto.FLOAT
    outputs = {"probs": ["N", a], "entropy": ["N"], "mutual_info": ["N"], "variance": ["N", a], "votes": ["N", a]}
    used = {i for g in graphs for node in g.node for i in node.input}
    made = {o for g in graphs for node in g.node for o in node.output}
    graph = helper.make_graph(
        [node for g in graphs for node in g.node] + tail, f"ensemble_of_{k}",
        [next(i for i in graphs[0].input if i.name == INPUT_NAME)],
        [helper.make_tensor_value_info(name, f, outputs[name]) for name in OUTPUT_NAMES],
        initializer=[t for g in graphs for t in g.initializer if t.name in used],
        value_info=[v for g in graphs for v in g.value_info if v.name in made])
    model = helper.make_model(graph, opset_imports=list(models[0].opset_import),
                              producer_name="crossing_assist.export.ensemble")
    model.ir_version = max(m.ir_version for m in models)
    if share:
        share_alike(model)
    onnx.checker.check_model(model)
    return model


#: Operators whose output is not a function of their inputs: two alike are two draws, never one.
NONDETERMINISTIC = frozenset({"RandomUniformLike", "RandomNormalLike", "RandomUniform", "RandomNormal",
                              "Multinomial", "Bernoulli", "Dropout"})


def share_alike(model: Any) -> int:
    """Run once what ``model``'s graph computes more than once (in place): a node with the same
    operator, attributes and inputs as an earlier one (an initializer counts by its dtype, shape
    and bytes, whatever its name) is dropped and its outputs read from the earlier node's, in
    graph order, so a chain shared from the input on (the members' frame fitting and frozen
    blocks) collapses to one. Nodes that draw at random (:data:`NONDETERMINISTIC`: each member's
    dropout masks stay its own), hold subgraphs, or name a graph output are never shared; the
    outputs are the graph's as before, bit for bit. Returns the number of nodes dropped."""
    import hashlib

    from onnx import AttributeProto, numpy_helper

    g = model.graph
    ident: dict[str, tuple] = {i.name: ("input", i.name) for i in g.input}
    for t in g.initializer:
        ident[t.name] = ("initializer", t.data_type, tuple(t.dims),
                         hashlib.sha256(numpy_helper.to_array(t).tobytes()).hexdigest())
    graph_outputs = {o.name for o in g.output}
    first: dict[tuple, list[str]] = {}   # a computation's identity -> the outputs of its first node
    alias: dict[str, str] = {}           # a dropped node's output -> the kept node's
    kept = []
    for node in g.node:
        inputs = [alias.get(i, i) for i in node.input]
        key = None
        if (node.op_type not in NONDETERMINISTIC and not graph_outputs.intersection(node.output)
                and all(a.type not in (AttributeProto.GRAPH, AttributeProto.GRAPHS) for a in node.attribute)):
            key = (node.domain, node.op_type,
                   tuple(a.SerializeToString() for a in sorted(node.attribute, key=lambda a: a.name)),
                   tuple(ident.get(i, ("name", i)) for i in inputs))
            if key in first:
                alias.update(zip(node.output, first[key]))
                continue
            first[key] = list(node.output)
        for j, name in enumerate(node.output):
            ident[name] = ("node", len(kept), j)
        del node.input[:]
        node.input.extend(inputs)
        kept.append(node)
    if not alias:
        return 0
    dropped = len(g.node) - len(kept)
    kept = [type(n).FromString(n.SerializeToString()) for n in kept]   # copies: the container is cleared next
    del g.node[:]
    g.node.extend(kept)
    used = {i for n in g.node for i in n.input}
    initializers = [t for t in g.initializer if t.name in used or t.name in graph_outputs]
    del g.initializer[:]
    g.initializer.extend(initializers)
    infos = [v for v in g.value_info if v.name not in alias]
    del g.value_info[:]
    g.value_info.extend(infos)
    return dropped


def _members(paths: Sequence[str]) -> tuple[list[Bundle], list[dict]]:
    """The member bundles, read and checked to agree on :data:`SHARED`, the MC settings (an
    ensemble bundle among them: but for how many members it has) and the precision."""
    bundles = [read_bundle(p) for p in paths]
    metas = [b.raw for b in bundles]
    alike = lambda meta, key: ({k: v for k, v in meta[key].items() if k != "members"}  # noqa: E731
                               if key == "mc" else meta.get(key))
    for i, meta in enumerate(metas[1:], 1):
        for key in (*SHARED, "mc", "precision"):
            if alike(meta, key) != alike(metas[0], key):
                raise ExportError(f"member {paths[i]} differs from {paths[0]} in {key!r} "
                                  f"({json.dumps(meta.get(key))[:80]} vs {json.dumps(metas[0].get(key))[:80]}); "
                                  "an ensemble's members must be exported alike")
    return bundles, metas


def _records(paths: Sequence[str], metas: Sequence[dict]) -> tuple[list, list, list]:
    """Each member's training record, provenance and figures on the calibration split, in order;
    an ensemble bundle's members each in turn."""
    training, provenance, measured = [], [], []
    for p, m in zip(paths, metas):
        if m["mc"].get("members", 1) > 1:
            training += m["training"]["ensemble"]
            provenance += m["provenance"].get("members", [])
            measured += m.get("metrics", {}).get("members", [])
        else:
            training.append({**m["training"], "temperature": m["calibration"]["temperature"], "bundle": str(p),
                             "checkpoint_metrics": m.get("metrics", {}).get("checkpoint", {})})
            provenance.append(m.get("provenance", {}))
            measured.append(m.get("metrics", {}).get("full_split", {}))
    return training, provenance, measured


def ensemble_bundle(cfg: EnsembleConfig, log: Callable[[str], None] = print) -> Path:
    """Merge ``cfg.members`` into one bundle at ``cfg.out``, its thresholds fitted on
    ``cfg.calib_data`` through the merged graph; returns the bundle's folder."""
    import onnx

    check_replaceable(cfg.out, force=cfg.force)
    try:
        bundles, metas = _members(cfg.members)
    except BundleError as exc:
        raise ExportError(str(exc)) from None
    model = merge_graphs([onnx.load(str(b.model_path)) for b in bundles])
    n_members = merged_members(model)
    log(f"merged {len(bundles)} graphs, {n_members} members: {len(model.graph.node)} nodes, {model.ByteSize() / 1e6:.1f} MB")
    first = metas[0]
    meta = {k: v for k, v in first.items() if k not in ("model_sha256", "model_size")}
    meta["mc"] = {**first["mc"], "members": n_members}
    training, provenance, measured = _records(cfg.members, metas)
    meta["training"] = {"ensemble": training}
    meta["provenance"] = {"command": " ".join(shlex.quote(a) for a in sys.argv) if sys.argv else "",
                          "created": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                          "calib_data": cfg.calib_data, "calib_split": cfg.calib_split,
                          "members": provenance}
    n = bundles[0].actions.n
    data = load_labelled(cfg.calib_data, cfg.calib_split, n, cfg.progress, bundles[0].geometry, bundles[0].input.size)
    check_calib_size(cfg.calib_data, cfg.calib_split, data.actions, cfg.min_calib)
    meta["calibration"] = cal.CalibrationResult(1.0, cfg.coverage, 0.0, 0, cfg.measure, 1.0).spec().to_json()
    calib, metrics = _fit_and_measure(model, meta, data, cfg, 1.0, None, log)
    meta["calibration"] = calib.spec().to_json()
    meta["metrics"] = {**metrics, "members": measured}
    set_metadata(model, meta)
    return write_bundle(cfg.out, model_bytes(model), meta, force=cfg.force)   # validated as it is written
