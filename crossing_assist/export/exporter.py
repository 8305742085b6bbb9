"""The export pipeline behind ``crossing-export``: checkpoint -> calibrated, checked bundle.

Steps (:func:`export_bundle`):

1. load the run's ``weights/best.pt`` (or a ``.pt`` file);
2. with ``calib_data``: read the labelled split; compute PyTorch MC logits of every frame;
   measure the calibration procedure by cross-fitting over folds cut by source
   (:func:`~crossing_assist.export.calibrate.cross_fit`: each fold measured with a temperature
   and conformal threshold fitted on the other folds), then fit the shipped temperature on all;
3. export the MC graph with that temperature (and, with ``int8``, quantise its convolutions
   on calibration frames);
4. run the shipped graph (in memory, :mod:`crossing_assist.inference`) through onnxruntime on
   every frame to fit the conformal and gate thresholds and record its metrics;
5. parity: a deterministic (T=1, p=0) export must match PyTorch to ``parity_tol``;
6. write ``model.onnx`` + ``bundle.json`` atomically, with the same facts in the graph's
   metadata.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import shlex
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np
import torch

from crossing_assist.actions import get_space
from crossing_assist.bundle import (
    INPUT_NAME,
    InputSpec,
    McSpec,
    check_replaceable,
    check_session,
    make_meta,
    parse_meta,
    read_bundle,
    write_bundle,
)
from crossing_assist.conformal import conformal_report
from crossing_assist.errors import UserError
from crossing_assist import inference
from crossing_assist.export import calibrate as cal
from crossing_assist.export.graph import BundleGraph, GraphSpec, export_graph, model_bytes, set_metadata
from crossing_assist.export.quantize import INT8_MODES, quantize_convs
from crossing_assist.geometry import VIEW_ZOOM_RANGE, Geometry, GeometryError, letterbox_geometry
from crossing_assist.runtime.belief import far_mass

if TYPE_CHECKING:  # annotations only: models is imported where it is used (_load_policy)
    from crossing_assist.models.policy import PolicyConfig

PARITY_TOL = 1e-4
#: Fewest labelled frames with a crossing (action != unknown) that ``--calib-data`` must hold;
#: fewer are refused unless ``--min-calib`` lowers it. On fewer frames the temperature, the
#: conformal threshold and the gate threshold are fitted to noise: the gate's 5 and 95 % clips
#: rest on two or three frames each, the accuracy the gate is fitted against is known only to
#: about +-7 points at 50 frames (+-18 at 8), and the split-conformal guarantee's slack is
#: 1/(n + 1). PTL val has 864 frames; a toy set of 8 with a model wrong on all of them gave
#: temperature 20 (its clip) and a gate threshold of ln 13 (every frame passes).
MIN_CALIB_CROSSINGS = 50
#: Gate measures an export fits (variance is per action: no single threshold to fit).
EXPORT_MEASURES = ("entropy", "mutual_info", "far_mass")


class ExportError(UserError):
    """A user-facing export failure (one line)."""


@dataclass(frozen=True)
class ExportConfig:
    """Options of ``crossing-export`` (the CLI is generated from these defaults)."""

    run: str
    out: str
    samples: int = 16
    p: float | None = None          # None: the checkpoint's own p (0.5 by default)
    mirror: bool = False            # mirror test-time augmentation in the graph (twice the backbone's cost)
    calib_data: str | None = None   # dataset folder (manifest.csv) with labelled frames
    calib_split: str = "val"
    calib_folds: int = 5            # folds (whole sources) for the held-out coverage measurement
    min_calib: int = MIN_CALIB_CROSSINGS   # fewest --calib-data frames with a crossing; fewer are refused
    coverage: float = 0.9
    measure: str = "entropy"
    gate_scale: float = 1.0         # multiplies the fitted gate threshold (chosen on held-out sources)
    gate_scale_portrait: float | None = None   # the same for portrait frames (None: portrait uses gate_scale's)
    view_zoom: float = 1.0          # > 1: narrower cameras' frames shown magnified up to this (schema 4)
    int8: bool = False
    int8_mode: str = "static"       # static: weights + activations; weights: int8 weights only
    int8_frames: int = 128
    parity_frames: int = 16
    parity_tol: float = PARITY_TOL
    batch: int = 32
    threads: int = 2
    seed: int = 0                   # the dropout masks while calibrating and measuring (PyTorch's, global RNG
                                    # untouched; onnxruntime's): the same checkpoint gives the same bundle.json
    progress: bool = True
    force: bool = False             # replace an existing --out even if it is not a bundle (deletes it)

    def __post_init__(self) -> None:
        checks = [
            (self.samples >= 1, f"--samples {self.samples}; valid: >= 1"),
            (self.p is None or 0.0 <= self.p < 1.0, f"--p {self.p}; valid: 0 <= p < 1"),
            (0.0 < self.coverage < 1.0, f"--coverage {self.coverage}; valid: 0 < coverage < 1"),
            (self.calib_folds >= 2, f"--calib-folds {self.calib_folds}; valid: >= 2"),
            (self.min_calib >= 1, f"--min-calib {self.min_calib}; valid: >= 1"),
            (0.05 <= self.gate_scale <= 20, f"--gate-scale {self.gate_scale}; valid: 0.05..20"),
            (self.gate_scale_portrait is None or 0.05 <= self.gate_scale_portrait <= 20,
             f"--gate-scale-portrait {self.gate_scale_portrait}; valid: 0.05..20"),
            (VIEW_ZOOM_RANGE[0] <= self.view_zoom <= VIEW_ZOOM_RANGE[1],
             f"--view-zoom {self.view_zoom}; valid: {VIEW_ZOOM_RANGE[0]:g}..{VIEW_ZOOM_RANGE[1]:g}"),
            (self.measure in EXPORT_MEASURES, f"--measure {self.measure!r}; valid: {', '.join(EXPORT_MEASURES)}"),
            (self.int8_mode in INT8_MODES, f"--int8-mode {self.int8_mode!r}; valid: {', '.join(INT8_MODES)}"),

            (inference.is_seed(self.seed), f"--seed {self.seed!r}; valid: {inference.SEED_RANGE}"),
        ]
        for ok, msg in checks:
            if not ok:
                raise ExportError(f"Invalid {msg}")
        if self.int8 and not self.calib_data:
            raise ExportError("--int8 needs --calib-data (real frames to calibrate the int8 ranges)")
        if (self.gate_scale != 1.0 or self.gate_scale_portrait is not None) and not self.calib_data:
            raise ExportError("--gate-scale / --gate-scale-portrait need --calib-data (they scale the threshold "
                              "fitted on it)")


@dataclass(frozen=True)
class ExportResult:
    path: Path
    size: int
    parity_max_abs: float
    calibration: cal.CalibrationResult
    metrics: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()


# ----------------------------------------------------------------------------- data


@dataclass(frozen=True)
class Labelled:
    """Labelled frames of one split: raw RGB images, action labels, bins, far_x, sources."""

    images: list
    actions: np.ndarray
    far_x: np.ndarray
    sources: np.ndarray

    def take(self, idx: np.ndarray) -> "Labelled":
        return Labelled([self.images[i] for i in idx], self.actions[idx], self.far_x[idx], self.sources[idx])


def load_labelled(data_dir: str, split: str, n_actions: int, progress: bool = True,
                  geometry: Geometry | None = None, canvas: tuple[int, int] | None = None) -> Labelled:
    """Read a dataset split (manifest.csv) as frames + action labels: each frame as the runtime
    gives it to the graph when ``geometry`` is given (its view crop at the FOV of the frame's
    orientation on ``canvas``, :meth:`Geometry.view`; a 4:3 landscape photo keeps every row),
    else raw. A frame whose default FOV is outside 20..170 degrees is an ExportError."""
    from tqdm import tqdm

    from crossing_assist.data_tools.images import load_frame
    from crossing_assist.data_tools.manifest import read_manifest

    ds = read_manifest(data_dir).split(split)
    if len(ds.rows) < 2:
        raise ExportError(f"Invalid --calib-data {data_dir}: split {split!r} has {len(ds.rows)} frames; need >= 2")
    images = [load_frame(ds.image_path(r), r.flags) for r in tqdm(ds.rows, desc="frames", disable=not progress, unit="img")]
    if geometry is not None:
        try:
            images = [geometry.camera_view(im, canvas) for im in images]
        except GeometryError as exc:
            raise ExportError(f"Invalid --calib-data {data_dir}: {exc}") from None
    actions = get_space(n_actions).bins_to_actions(ds.labels())
    if not (actions != 0).any():
        raise ExportError(f"Invalid --calib-data {data_dir}: split {split!r} has no frame with a crossing label "
                          f"(all {len(actions)} unknown); calibration needs labelled crossings")
    return Labelled(images, actions, ds.far_x(), np.asarray([r.source for r in ds.rows]))


def check_calib_size(data_dir: str, split: str, actions: np.ndarray, min_calib: int = MIN_CALIB_CROSSINGS) -> None:
    """ExportError unless the calibration frames' action labels ``actions`` [N] hold at least
    ``min_calib`` frames with a crossing (:data:`MIN_CALIB_CROSSINGS`)."""
    n = int((np.asarray(actions) != 0).sum())
    if n < min_calib:
        raise ExportError(f"Invalid --calib-data {data_dir}: split {split!r} has {n} frames with a crossing "
                          f"(of {len(actions)}); calibrating a gate needs at least {min_calib}, "
                          "fewer fit it to noise: label more frames or pass --min-calib N to accept fewer")


def _batched(images: Sequence[np.ndarray], batch: int):
    """Consecutive runs of same-shape frames, at most ``batch`` long."""
    i = 0
    while i < len(images):
        j = i + 1
        while j < len(images) and j - i < batch and images[j].shape == images[i].shape:
            j += 1
        yield np.stack(images[i:j])
        i = j


@torch.no_grad()
def torch_logits(graph: BundleGraph, images: Sequence[np.ndarray], batch: int, progress: bool) -> np.ndarray:
    """PyTorch logits [T, N, A] of the graph's policy (same preprocessing as the ONNX graph)."""
    from tqdm import tqdm

    out = [graph.logits(torch.from_numpy(x)) for x in
           tqdm(list(_batched(images, batch)), desc="torch logits", disable=not progress, unit="batch")]
    return torch.cat(out, 1).numpy()


# ----------------------------------------------------------------------------- pipeline


def _load_policy(run: str):
    from crossing_assist.models.checkpoint import CheckpointError, load_policy, run_checkpoint

    try:
        ckpt = run_checkpoint(run)
        return load_policy(ckpt), ckpt
    except CheckpointError as exc:
        raise ExportError(str(exc)) from None


def _spec(config: PolicyConfig, samples: int, p: float, temperature: float = 1.0, mirror: bool = False) -> GraphSpec:
    """The graph of a policy config; a checkpoint from before the geometry contract (no
    ``fit``) was trained on stretched frames and keeps ``stretch`` (PolicyConfig's default)."""
    return GraphSpec(size=config.input_size, mean=config.mean, std=config.std, samples=samples, p=p,
                     temperature=temperature, fit=config.fit, pad_rgb=config.pad_rgb, mirror=mirror)


def _geometry(config: PolicyConfig, spec: GraphSpec, view_zoom: float = 1.0) -> Geometry:
    """Letterboxed models see the training camera's view: consumers crop rows beyond it (schema 3),
    and frames narrower than the phone's 4:3 sensor (9:16 video) get their crop's FOV
    (``sensor_aspect``); ``view_zoom`` > 1 shows narrower cameras' frames magnified up to it
    (schema 4). A stretched model with a view zoom is an ExportError."""
    letterbox = spec.fit == "letterbox"
    if view_zoom != 1 and not letterbox:
        raise ExportError(f"Invalid --view-zoom {view_zoom}: the checkpoint stretches frames (fit {spec.fit}); "
                          "a view zoom needs a letterbox model")
    if letterbox:
        return letterbox_geometry(config.fov_deg, spec.pad_rgb, view_zoom)
    return Geometry(fit=spec.fit, pad_rgb=spec.pad_rgb, train_fov_deg=config.fov_deg)


def parity_check(policy, spec: GraphSpec, frames: np.ndarray) -> float:
    """Max |probs| difference between the deterministic (T=1, p=0, temperature 1) ONNX graph
    under onnxruntime and PyTorch, on ``frames`` [N, H, W, 3] uint8. (A fitted temperature
    below 1 would magnify float32 rounding of large logits; it is one division, tested apart.)"""
    import onnxruntime as ort

    det = dataclasses.replace(spec, samples=1, p=0.0, temperature=1.0)
    sess = ort.InferenceSession(model_bytes(export_graph(policy, det)))
    got = sess.run(["probs"], {INPUT_NAME: frames})[0]
    with torch.no_grad():
        want = BundleGraph(policy, det)(torch.from_numpy(frames))[0].numpy()
    return float(np.abs(got - want).max())


def _probe_frames(data: Labelled | None, spec: GraphSpec, n: int) -> np.ndarray:
    if data is not None:
        first = data.images[0].shape
        same = [im for im in data.images if im.shape == first][:n]
        return np.stack(same)
    rng = np.random.default_rng(0)
    h, w = spec.size
    return rng.integers(0, 256, (4, h + 16, w + 24, 3), dtype=np.uint8)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _meta(policy, ckpt: Path, spec: GraphSpec, calib: cal.CalibrationResult, precision: str,
          metrics: dict, cfg: ExportConfig) -> dict:
    c = policy.config
    return make_meta(
        n_actions=policy.n_actions,
        input=InputSpec(size=spec.size, mean=spec.mean, std=spec.std, resize="bilinear, antialiased"),
        geometry=_geometry(c, spec, cfg.view_zoom),
        mc=McSpec(spec.samples, spec.p, spec.mirror),
        calibration=calib.spec(),
        precision=precision,
        training={"backbone": c.backbone, "head": c.head,
                  **({"feature_stride": c.feature_stride} if c.feature_stride else {}),
                  "weights_source": c.weights_source, "licence": c.licence,
                  "data": c.data, "counts": dict(c.counts),
                  "majority_action": c.majority_action, "checkpoint": str(ckpt),
                  "checkpoint_sha256": _sha256(ckpt)},
        metrics=metrics,
        provenance={"command": " ".join(shlex.quote(a) for a in sys.argv) if sys.argv else "",
                    "created": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                    "calib_data": cfg.calib_data, "calib_split": cfg.calib_split},
    )


def _measure(probs_out: dict, data: Labelled, threshold: float, n_actions: int, majority: int | None) -> dict:
    from crossing_assist.models.metrics import compute_metrics

    m = compute_metrics(probs_out["probs"], data.actions, n_actions, data.far_x, majority=majority)
    keep = ("n", "accuracy", "bin_mae", "majority_accuracy", "majority_bin_mae", "balanced_accuracy",
            "top3_accuracy", "nll", "ece", "far_x_error")
    out = {k: m[k] for k in keep if k in m}
    rep = conformal_report(probs_out["probs"], data.actions, threshold)
    out.update({"coverage": rep["coverage"], "mean_set_size": rep["mean_size"], "empty_sets": rep["empty"]})
    return out


def _fit_and_measure(model: Any, meta: dict, data: Labelled, cfg: ExportConfig, temperature: float,
                     majority: int | None, log: Callable[[str], None]) -> tuple[cal.CalibrationResult, dict]:
    """Fit the conformal and gate thresholds on the shipped graph's onnxruntime outputs for
    every labelled frame and record the graph's metrics there (coverage there is in-sample:
    the held-out figure is ``cross_fit``). In memory: the graph with ``meta`` embedded, checked
    against ``meta`` as a written bundle would be. Logs a ``warning: ...`` line for a gate fit that
    ended on a clip (:func:`cal.gate_warnings`). The callers refuse too few frames with a crossing
    first (:func:`check_calib_size`), before any model work."""
    set_metadata(model, meta)
    bundle = parse_meta(meta, need_bytes=False)
    sess = inference.session_from_bytes(model_bytes(model), seed=cfg.seed)
    check_session(bundle, sess)
    got = inference.predict(sess, bundle.actions.n, data.images, batch=cfg.batch, progress=cfg.progress)
    correct = got["probs"].argmax(1) == data.actions
    u = np.array([far_mass(p) for p in got["probs"]]) if cfg.measure == "far_mass" else got[cfg.measure]
    gate = cal.fit_gate(u, correct)
    fitted = gate.threshold
    calib = cal.CalibrationResult(
        temperature=temperature, coverage=cfg.coverage,
        threshold=cal.conformal_threshold(got["probs"], data.actions, cfg.coverage),
        n_frames=len(data.actions), measure=cfg.measure, uncertainty_threshold=cfg.gate_scale * fitted,
        portrait_uncertainty_threshold=None if cfg.gate_scale_portrait is None else cfg.gate_scale_portrait * fitted,
        fitted_uncertainty_threshold=fitted)
    full = _measure(got, data, calib.threshold, meta["actions"]["n"], majority)
    log(f"{cfg.calib_split} through onnxruntime (T={meta['mc']['samples']}): accuracy {full['accuracy']:.4f} "
        f"on {full['n']} frames")
    for warning in cal.gate_warnings(u, gate, calib.uncertainty_threshold, cfg.measure, meta["actions"]["n"]):
        log(f"warning: {warning}")
    return calib, {"full_split": full}


def export_bundle(cfg: ExportConfig, log: Callable[[str], None] = print) -> ExportResult:
    """Run the whole pipeline (module docstring) and return where the bundle went."""
    check_replaceable(cfg.out, force=cfg.force)  # before minutes of work, and again when writing
    torch.set_num_threads(max(1, cfg.threads))
    policy, ckpt = _load_policy(cfg.run)
    canvas = policy.config.input_size
    geometry = _geometry(policy.config, _spec(policy.config, 1, 0.0), cfg.view_zoom)   # a bad --view-zoom: before minutes of work
    n = policy.n_actions
    p = policy.config.p if cfg.p is None else cfg.p
    majority = policy.config.majority_action or None   # 0 (unknown): runs whose baseline counted negatives
    data = load_labelled(cfg.calib_data, cfg.calib_split, n, cfg.progress, geometry, canvas) if cfg.calib_data else None
    calib, metrics, notes = cal.uncalibrated(n, cfg.measure), {}, []
    if data is not None:
        check_calib_size(cfg.calib_data, cfg.calib_split, data.actions, cfg.min_calib)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(cfg.seed)
            logits = torch_logits(BundleGraph(policy, _spec(policy.config, cfg.samples, p, mirror=cfg.mirror)), data.images,
                                  cfg.batch, cfg.progress)
        folds = cal.source_folds(data.sources, cfg.calib_folds)
        cross = cal.cross_fit(logits, data.actions, folds, cfg.coverage, data.sources)
        one = len(set(data.sources)) == 1   # then the folds are contiguous blocks: not held out by source
        log(f"held-out conformal coverage {cross['coverage']:.3f} (target {cfg.coverage:.2f}, mean set "
            f"{cross['mean_set_size']:.2f}) over {len(folds)} " +
            (f"contiguous blocks of the one source {data.sources[0]} (not held out by source; calibrate on "
             "several sources for that): " if one else "folds by source: ") +
            ", ".join(f"{f'block {i + 1}' if one else '+'.join(f['sources'])} {f['coverage']:.3f}"
                      for i, f in enumerate(cross["folds"])))
        temperature = cal.fit_temperature(logits, data.actions)
        log(f"temperature {temperature:.3f} (NLL {cal.nll(logits, data.actions):.4f} -> "
            f"{cal.nll(logits, data.actions, temperature):.4f} on {len(data.actions)} frames)")
        if warning := cal.temperature_warning(temperature):
            log(f"warning: {warning}")
    else:
        temperature = 1.0
        notes.append("not calibrated: no --calib-data (temperature 1, every action in every conformal set)")
    spec = _spec(policy.config, cfg.samples, p, temperature, cfg.mirror)
    t0 = time.time()
    model = export_graph(policy, spec)
    log(f"exported the graph in {time.time() - t0:.1f} s")
    precision, fp32_model = "fp32", model
    if cfg.int8:
        perm = np.random.default_rng(0).permutation(len(data.images))
        k = min(cfg.int8_frames, len(perm) // 2)  # keep frames the ranges never saw to measure on
        pick, unseen = np.sort(perm[:k]), np.sort(perm[k:])
        t0 = time.time()
        model = quantize_convs(model, [data.images[i] for i in pick], mode=cfg.int8_mode)
        log(f"quantised the convolutions to int8 ({cfg.int8_mode}) in {time.time() - t0:.1f} s")
        precision = "int8"
    parity = parity_check(policy, spec, _probe_frames(data, spec, cfg.parity_frames))
    log(f"parity (fp32 graph, T=1, p=0) onnxruntime vs PyTorch: max |probs diff| = {parity:.2e} (tolerance {cfg.parity_tol:g})")
    if parity > cfg.parity_tol:
        raise ExportError(f"parity check failed: max |probs diff| {parity:.2e} > {cfg.parity_tol:g}; "
                          "the ONNX graph does not reproduce the PyTorch model")
    out = Path(cfg.out)
    if data is not None:
        provisional = cal.CalibrationResult(temperature, cfg.coverage, 0.0, 0, cfg.measure, calib.uncertainty_threshold)
        meta = _meta(policy, ckpt, spec, provisional, precision, {}, cfg)
        calib, metrics = _fit_and_measure(model, meta, data, cfg, temperature, majority, log)
        metrics["cross_fit"] = cross
        metrics["checkpoint"] = policy_metrics(ckpt)
        if cfg.int8:  # measured on the frames the int8 ranges were not calibrated on
            metrics["int8_vs_fp32"] = {"mode": cfg.int8_mode,
                                       **compare_precisions(model, fp32_model, meta, data.take(unseen), cfg.batch,
                                                            seed=cfg.seed)}
    metrics["parity_max_abs"] = parity
    meta = _meta(policy, ckpt, spec, calib, precision, metrics, cfg)
    set_metadata(model, meta)
    data_bytes = model_bytes(model)
    write_bundle(out, data_bytes, meta, force=cfg.force)
    read_bundle(out)
    return ExportResult(out, len(data_bytes), parity, calib, metrics, tuple(notes))


def policy_metrics(ckpt: Path) -> dict:
    """The checkpoint's own recorded metrics (``metrics.val``), for the comparison in bundle.json."""
    from crossing_assist.models.checkpoint import load_checkpoint

    m = load_checkpoint(ckpt).get("metrics", {})
    return {k: v for k, v in (m.get("val") or {}).items() if isinstance(v, (int, float)) and not
            (isinstance(v, float) and math.isnan(v))}


def _latency_ms(sess: Any, frame: np.ndarray, repeats: int = 10) -> float:
    sess.run(None, {INPUT_NAME: frame})
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sess.run(None, {INPUT_NAME: frame})
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1000)


def compare_precisions(model: Any, fp32_model: Any, meta: dict, data: Labelled, batch: int,
                       repeats: int = 5, seed: int | None = None) -> dict:
    """Size (bytes), single-frame latency (ms, median of 10, default session options) and
    evaluation-part accuracy (mean over ``repeats`` MC runs) of the int8 graph against fp32."""
    n = parse_meta(meta, need_bytes=False).actions.n
    b32, b8 = model_bytes(fp32_model), model_bytes(model)
    s32, s8 = inference.session_from_bytes(b32, seed=seed), inference.session_from_bytes(b8, seed=seed)
    acc = {}
    for name, sess in (("fp32", s32), ("int8", s8)):  # mean over repeats: MC noise moves argmaxes
        acc[name] = float(np.mean([(inference.predict(sess, n, data.images, batch=batch)["probs"]
                                    .argmax(1) == data.actions).mean() for _ in range(repeats)]))
    frame = data.images[0][None]
    return {"size_fp32": len(b32), "size_int8": len(b8), "size_ratio": len(b8) / len(b32),
            "ms_fp32": _latency_ms(s32, frame), "ms_int8": _latency_ms(s8, frame),
            "accuracy_fp32": acc["fp32"], "accuracy_int8": acc["int8"], "n": int(len(data.actions)),
            "accuracy_repeats": repeats}
