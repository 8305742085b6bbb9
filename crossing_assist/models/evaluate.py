"""``crossing-eval``: metrics.json and plots for a checkpoint (or a bundle) on a dataset split.

Writes into ``out``: ``metrics.json`` (see :func:`crossing_assist.models.metrics.compute_metrics`,
plus where the numbers came from), ``confusion_matrix.png``, ``reliability.png`` and
``examples.png`` (frames with the true strip, the top-3 predicted strips and the activation
map of the predicted action: the thesis's Figures 3.4-3.6).
"""

from __future__ import annotations

from typing import Any

import json
import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..actions import get_space
from ..data_tools.images import ImageError, frame_fov, load_frame
from ..data_tools.manifest import Dataset, atomic_write_text, read_manifest
from ..geometry import GeometryError, check_fov, content_window, letterbox
from ..inference import SEED_RANGE, is_seed
from .cache import compute_features
from .checkpoint import load_checkpoint, load_policy, run_checkpoint
from .config import ConfigError
from .data import make_variants, normalise, resize_rgb
from .plots import plot_confusion, plot_examples, plot_reliability
from .policy import Policy
from .train import Split, predict_split


@dataclass(frozen=True)
class EvalConfig:
    """One evaluation: exactly one of ``run`` (folder or .pt) and ``bundle``."""

    data: str
    run: str | None = None
    bundle: str | None = None
    split: str = "val"
    out: str | None = None
    samples: int = 1
    examples: int = 12
    tta_mirror: bool = False
    actions: int | None = None      # score a 13-action model in a coarser space (4 or 8)
    listen: bool = True             # bundles: play each frame through the runtime (what the user hears)
    portrait: int = 3               # bundles: portrait views per photo (phone and 3:4 window), beside landscape
    negatives: str | None = None    # a dataset of no-crossing frames (its SPLIT rows) for the silence rate
    clip_seconds: float = 1.0       # each photo is played as a still clip this long at 10 fps
    fov_deg: float | None = None    # bundles: the frames' camera FOV (a row's fov= flag wins; None: the bundle's)
    scan_dps: float = 0.0           # bundles: > 0 also plays each photo as a scan at this turn rate (deg/s)
    scan_deg: float = 20.0          # the scan's amplitude either side of straight ahead
    scan_heard_s: float = 0.0       # judge each scan decision this long after its frame's capture (when heard)
    seed: int = 0                   # the MC-dropout masks' seed (onnxruntime / torch): a rerun gives the same figures
    threads: int = 2
    cache_dir: str = "runs/.cache"
    progress: bool = True

    def __post_init__(self) -> None:
        if (self.run is None) == (self.bundle is None):
            raise ConfigError("Invalid arguments: give exactly one of --run and --bundle")
        if self.samples < 1:
            raise ConfigError(f"Invalid samples {self.samples}; valid: >= 1")
        if self.examples < 0:
            raise ConfigError(f"Invalid examples {self.examples}; valid: >= 0")
        if self.actions not in (None, 4, 8, 13):
            raise ConfigError(f"Invalid actions {self.actions}; valid: 4, 8, 13")
        if not 0 <= self.portrait <= 12:
            raise ConfigError(f"Invalid portrait {self.portrait}; valid: 0..12 windows a photo")
        if not 0.1 <= self.clip_seconds <= 10:
            raise ConfigError(f"Invalid clip_seconds {self.clip_seconds}; valid: 0.1..10")
        if not is_seed(self.seed):
            raise ConfigError(f"Invalid seed {self.seed!r}; valid: {SEED_RANGE}")
        if self.scan_dps < 0 or (self.scan_dps and not (0 < self.scan_deg < 60 and self.scan_dps <= 360)):
            raise ConfigError(f"Invalid --scan {self.scan_dps:g} deg/s by {self.scan_deg:g} deg; valid: 0 (off) or "
                              "up to 360 deg/s, by 0..60 deg")
        if not 0 <= self.scan_heard_s <= 1:
            raise ConfigError(f"Invalid --heard-after {self.scan_heard_s:g} s; valid: 0..1 s after the frame's capture")
        if self.fov_deg is not None:
            if self.run is not None:
                raise ConfigError("Invalid arguments: --fov is the camera the runtime plays a bundle's frames at; "
                                  "give --bundle (export the run first)")
            try:
                check_fov(self.fov_deg)
            except GeometryError as exc:
                raise ConfigError(f"Invalid --fov: {exc}") from None


def _split(cfg: EvalConfig) -> Dataset:
    ds = read_manifest(cfg.data)
    part = ds.split(cfg.split)
    if len(part) == 0:
        raise ConfigError(f"Invalid --split {cfg.split}: {cfg.data} has no {cfg.split} rows")
    return part


def _example_indices(pred: np.ndarray, labels: np.ndarray, k: int) -> np.ndarray:
    """Up to k frames, half errors and half correct, spread evenly over the split."""
    wrong, right = np.flatnonzero(pred != labels), np.flatnonzero(pred == labels)
    take = lambda a, m: a[np.linspace(0, len(a) - 1, min(m, len(a))).astype(int)] if len(a) else a  # noqa: E731
    idx = np.concatenate([take(wrong, k // 2), take(right, k - min(k // 2, len(wrong)))])
    return np.sort(idx[:k]).astype(int)


@torch.no_grad()
def activation_maps(policy: Policy, images: list[np.ndarray], actions: np.ndarray) -> list[np.ndarray]:
    """Per frame, the head's activation map of ``actions[i]`` (spatial: 1 x 12 column shares;
    thesis heads: h x w score / CAM map)."""
    policy.eval()
    size = policy.config.input_size
    if policy.config.fit == "letterbox":
        fitted = [letterbox(i, size) for i in images]
        window = torch.tensor([content_window(i.shape[0], i.shape[1], size) for i in images], dtype=torch.float32)
    else:
        fitted, window = [resize_rgb(i, size) for i in images], None
    x = torch.from_numpy(normalise(np.stack(fitted), policy.config.mean, policy.config.std))
    feats = policy.backbone.forward_features(x)
    head = policy.head
    maps = head.column_maps(feats, window)[:, :, None, :] if hasattr(head, "column_maps") else head.score_maps(feats)
    return [maps[i, int(a)].numpy() for i, a in enumerate(actions)]


def _eval_checkpoint(cfg: EvalConfig, part: Dataset) -> tuple[np.ndarray, dict, Policy]:
    path = run_checkpoint(cfg.run)
    policy = load_policy(path)
    ck = load_checkpoint(path)
    c = policy.config
    start = len(policy.backbone.blocks) if c.frozen_blocks is None else c.frozen_blocks
    fs = compute_features(policy.backbone, start, part, c.input_size, make_variants(cfg.tta_mirror),
                          c.fov_deg, Path(cfg.cache_dir), progress=cfg.progress, desc=f"features {cfg.split}",
                          fit=c.fit)
    split = Split(torch.from_numpy(np.array(fs.feats)), fs.labels, fs.far_x, torch.from_numpy(np.asarray(fs.window)))
    probs = predict_split(policy, split, start, samples=cfg.samples)
    if cfg.tta_mirror:  # average each frame with its mirror image (actions mapped back)
        space = get_space(policy.n_actions)
        back = [space.mirror_action(a) for a in range(policy.n_actions)]
        probs = 0.5 * (probs[0::2] + probs[1::2][:, back])
    info = {"source": "checkpoint", "checkpoint": str(path), "epoch": int(ck.get("epoch", 0)),
            "samples": cfg.samples, "tta_mirror": cfg.tta_mirror, "majority_from": "train" if c.majority_action is not None else "eval labels",
            "backbone": c.backbone, "head": c.head}
    return probs, info, policy


def _eval_bundle(cfg: EvalConfig, part: Dataset) -> tuple[np.ndarray, dict, Any]:
    from .. import inference

    bundle, sess = inference.open_session(cfg.bundle, threads=cfg.threads, seed=cfg.seed)
    # what the runtime's Engine.predict gives the graph: each frame's rows as the training camera
    # saw them at the FOV of the frame's orientation (schema 3's view crop; all rows before)
    images = []
    for r in part.rows:
        img = load_frame(part.image_path(r), r.flags)
        try:
            images.append(bundle.geometry.camera_view(img, bundle.input.size, _fov(cfg, part, r)))
        except GeometryError as exc:   # the runtime refuses such a frame (stop cue): say which, do not guess
            raise ConfigError(f"{part.image_path(r)}: {img.shape[1]}x{img.shape[0]} is too narrow for a camera "
                              f"({exc}); the runtime stops on such frames: leave it out of the split") from None
    out = inference.predict(sess, bundle.actions.n, images, progress=cfg.progress)
    majority = bundle.training.get("majority_action")
    info = {"source": "bundle", "bundle": str(cfg.bundle), "samples": int(bundle.mc.samples),
            "majority_from": "train" if majority is not None else "eval labels"}
    return np.asarray(out["probs"], dtype=np.float64), info, bundle


def _bundle_conformal(bundle, probs: np.ndarray, labels: np.ndarray) -> dict:
    """Empirical coverage and set sizes of the bundle's conformal sets on these frames."""
    from ..conformal import bundle_conformal_report

    return bundle_conformal_report(bundle, probs, labels)


#: The largest multiple of the bundle's threshold crossing-eval sweeps (scripts/choose_gate.py --max-scale).
GATE_TOP = 4.0


def gate_scales(steps: int = 8, top: float = GATE_TOP) -> tuple[float, ...]:
    """Gate thresholds to sweep, as multiples of the bundle's: ``steps`` a doubling, from 1/4 to
    ``top`` (a power of two >= 1; 1 included)."""
    doublings = math.log2(top)
    if top < 1 or doublings != round(doublings):
        raise ValueError(f"sweep top {top:g}: a power of two >= 1 (1, 2, 4, 8, ...)")
    return tuple(2.0 ** (j / steps) for j in range(-2 * steps, round(doublings) * steps + 1))


#: The gate thresholds crossing-eval sweeps (scripts/choose_gate.py's default grid).
GATE_SCALES = gate_scales()


def _fov(cfg: EvalConfig, ds: Dataset, row) -> float | None:
    """A frame's camera FOV: its ``fov=`` flag, else ``--fov``, else None (the bundle's default)."""
    try:
        fov = frame_fov(row.flags)
    except ImageError as exc:
        raise ConfigError(f"{ds.image_path(row)}: {exc}") from None
    return cfg.fov_deg if fov is None else fov


def _views(cfg: EvalConfig, rows: list, geometry) -> dict[str, list[tuple[np.ndarray, float | None, int, bool, float | None]]]:
    """The frames a user's phone would give of ``rows`` ((dataset, row) pairs), each with its
    camera FOV (None = the bundle's default): each photo as taken (landscape) and, with
    ``cfg.portrait``, its portrait views (:func:`~crossing_assist.data_tools.augment.user_views`:
    a phone held in portrait at the bundle's portrait FOV, and 3:4 windows).
    A frame whose camera is known (its ``fov=`` flag, e.g. from its EXIF, or ``--fov``) is played at
    that FOV, and cut into portrait views only when that is the training camera's (within
    ``SAME_CAMERA_DEG``): the views assume a photo of the training camera."""
    from ..data_tools.augment import PORTRAIT_SETS, user_views
    from ..geometry import SAME_CAMERA_DEG

    views: dict[str, list] = {"landscape": [], **({k: [] for k in PORTRAIT_SETS} if cfg.portrait else {})}
    for ds, r in rows:
        fov = _fov(cfg, ds, r)
        training_camera = fov is None or abs(fov - geometry.train_fov_deg) <= SAME_CAMERA_DEG
        for name, vs in user_views(load_frame(ds.image_path(r), r.flags), r.far_x, r.label,
                                   cfg.portrait if training_camera else 0, geometry).items():
            views[name] += [(*v[:4], fov) if name == "landscape" and fov is not None else v for v in vs]
    return views


#: The narrow camera a scan also plays (``crossing-eval --scan`` with ``--portrait``): a 3:4 window
#: in the middle of each photo, turning with it (the portrait_window view's camera, ~41 deg across).
SCAN_WINDOW_ASPECT = 3 / 4


def scan_clips(engine, image: np.ndarray, far_x: float | None, label: int, psi: np.ndarray,
               fov_deg: float | None = None, window: float | None = None,
               phone_fov_deg: float | None = None) -> tuple[list, np.ndarray, np.ndarray]:
    """One photo (scaled to a camera stream's width) seen by a camera turned ``psi[j]`` degrees at
    each frame (:func:`~crossing_assist.data_tools.augment.yaw`: the scene beyond the photo black,
    the goal moved, ``unknown`` once it leaves the view), through ``engine``: the predictions, the
    goal's strip per frame and the yaw rate read from the frames at the scan's frame rate
    (:class:`~crossing_assist.runtime.visual_yaw.VisualYaw`, as the pipeline reads it without a
    gyroscope). ``fov_deg``: the photo's camera (None: the bundle's for its size). ``window``: a
    narrower camera turning with it instead, which sees the middle window of this aspect (width /
    height) of each turned view at the window's own FOV; a goal beside the window but still in the
    photo is the edge strip (:func:`~crossing_assist.data_tools.augment.crop_window`).
    ``phone_fov_deg``: a phone held in portrait (3:4, this FOV across) turning with it instead, which
    sees the middle of each turned view as :func:`~crossing_assist.data_tools.augment.phone_views`
    cuts it (the ``portrait`` view of choose_gate and crossing-eval)."""
    from ..data_tools.augment import crop_window, phone_views, yaw
    from ..geometry import window_fov
    from ..runtime.listen import SCAN_FPS
    from ..runtime.sources import CAMERA_WIDTH, scale_to_width
    from ..runtime.visual_yaw import VisualYaw

    if window is not None and phone_fov_deg is not None:
        raise ValueError("a scan is seen by a window or by a phone, not both")
    image = scale_to_width(image, CAMERA_WIDTH)
    fov = engine.camera_fov(image.shape[1], image.shape[0], fov_deg)
    seen, preds, labels, rates = VisualYaw(), [], [], []
    for j, p in enumerate(psi):
        view, x, lab, _ = yaw(image, far_x, label, float(p), fov)
        cam, real = fov, view.shape[0]
        if window is not None:
            view, x, lab = crop_window(view, x, lab, window, 0.5)
            cam = window_fov(view.shape[1] / image.shape[1], fov)
        elif phone_fov_deg is not None:
            view, x, lab, _ = phone_views(view, x, lab, 1, fov_deg=phone_fov_deg, train_fov_deg=fov)[0]
            cam = phone_fov_deg
        preds.append(engine.predict(view, cam))
        labels.append(lab)
        # the turn is read from the rows the photo has: a phone's rows above and below it, which
        # phone_views repeats from the photo's edge rows, would show a real scene (repeated, they
        # cost the reading 4.2 deg/s against 0.5 on sam's photos scanned)
        top = max(0, view.shape[0] - real) // 2 if phone_fov_deg is not None else 0
        rows = view if not top else np.ascontiguousarray(view[top:top + real])
        rates.append(seen.update(rows, j / SCAN_FPS, cam))
    return preds, np.asarray(labels, np.int64), np.asarray(rates, float)


def _listen_scans(cfg: EvalConfig, engine, part: Dataset) -> dict:
    """The split's photos with a measured goal, each played as a scan (:func:`scan_clips`,
    :func:`~crossing_assist.runtime.listen.scan_yaw`) and judged per way the turn reaches the
    decision logic (:func:`~crossing_assist.runtime.listen.judge_scans`); with ``cfg.portrait``
    also as the narrow camera (``portrait_window``: :data:`SCAN_WINDOW_ASPECT`), and the
    ``--negatives`` frames as scans too (``no_crossing``: every frame after the still second
    should be silent)."""
    from tqdm import tqdm

    from ..runtime.listen import LATE_READINGS, SCAN_YAW_INPUTS, judge_scans, scan_yaw

    psi = scan_yaw(cfg.scan_deg, cfg.scan_dps)

    def play(rows: list, desc: str, window: float | None = None) -> dict:
        clips, labels, rates = [], [], []
        for ds, r in tqdm(rows, desc=desc, disable=not cfg.progress or not rows, unit="photo"):
            image = load_frame(ds.image_path(r), r.flags)
            if window is not None and image.shape[1] <= image.shape[0]:
                continue   # a window narrower than the photo is cut from landscape photos only
            preds, labs, seen = scan_clips(engine, image, r.far_x, r.label, psi, _fov(cfg, ds, r), window)
            clips.append(preds)
            labels.append(labs)
            rates.append(seen)
        if not clips:
            return {"photos": 0}
        fovs = Counter(round(p.fov_deg, 1) for c in clips for p in c[:1] if p.fov_deg is not None)
        return {"photos": len(clips), "camera_fov_deg": {f"{k:g}": n for k, n in sorted(fovs.items())},
                **judge_scans(engine, clips, np.asarray(labels), psi, np.asarray(rates), heard_after_s=cfg.scan_heard_s)}

    rows = [(part, r) for r in part.rows if r.far_x is not None and r.label != 0]
    if not rows:
        return {}
    out = {"rate_dps": cfg.scan_dps, "amplitude_deg": cfg.scan_deg, "frames": len(psi), "heard_after_s": cfg.scan_heard_s,
           **play(rows, "listen scans")}
    # a narrow camera is cut from photos of the bundle's own camera only (as the portrait views are)
    wide = [(ds, r) for ds, r in rows if _fov(cfg, ds, r) is None]
    if cfg.portrait and wide and (narrow := play(wide, "listen scans, 3:4 window", SCAN_WINDOW_ASPECT))["photos"]:
        out["portrait_window"] = narrow
    if negatives := _negative_rows(cfg):
        out["no_crossing"] = none = play(negatives, "listen scans, no crossing")
        for k in (*SCAN_YAW_INPUTS, *LATE_READINGS):   # every judged frame is out of view: silence is the beacon off
            if k in none:
                none[k]["silence"] = 1.0 - none[k]["out_of_view_on"]
    return out


def _negative_rows(cfg: EvalConfig) -> list:
    """``cfg.negatives``' no-crossing rows of the split, as (dataset, row) pairs."""
    if not cfg.negatives:
        return []
    neg = read_manifest(cfg.negatives).split(cfg.split)
    return [(neg, r) for r in neg.rows if r.label == 0]


def listen_bundle(cfg: EvalConfig, out: Path) -> dict:
    """What the user hears, per view (landscape / portrait / portrait_window): the runtime's decisions on every
    frame played as a still clip, the model's own accuracy on the same frames, and the
    risk-coverage curve of the view's gate threshold (its frames + no-crossing frames)."""
    from tqdm import tqdm

    from ..runtime.engine import Engine
    from ..runtime.listen import Listener, choose_threshold, error_stats, heading_errors, summarise
    from .metrics import compute_metrics
    from .plots import plot_risk_coverage

    engine = Engine(cfg.bundle, threads=cfg.threads, seed=cfg.seed)
    space = engine.space
    result: dict = {"clip_seconds": cfg.clip_seconds, "fps": 10.0}
    part = _split(cfg)
    # every view's frames of the split are played before any no-crossing frame of --negatives: the
    # engine's MC-dropout draws run on in play order, so adding negatives leaves the figures on the
    # frames with a crossing as they were
    sets = [_views(cfg, [(part, r) for r in part.rows], engine.bundle.geometry),
            _views(cfg, _negative_rows(cfg), engine.bundle.geometry)]
    listeners = {name: Listener(engine, cfg.clip_seconds, 10.0) for name in sets[0]}
    for views in sets:
        for name, frames in views.items():
            for img, _, lab, _, fov in tqdm(frames, desc=f"listen {name}", disable=not cfg.progress or not frames,
                                            unit="frame"):
                listeners[name].add(img, lab, fov)
    for name, lis in listeners.items():
        frames = sets[0][name] + sets[1][name]
        if not frames:   # portrait views of a split with no landscape photo
            continue
        known = np.asarray([lab != 0 for _, _, lab, _, _ in frames])
        probs = np.stack([c[0].probs if c[0].ok else np.full(space.n, 1 / space.n) for c in lis.clips])
        labels = space.bins_to_actions(np.asarray([lab for _, _, lab, _, _ in frames]))
        far_x = np.asarray([np.nan if fx is None else fx for _, fx, _, _, _ in frames], float)
        m = compute_metrics(probs[known], labels[known], space.n, far_x[known]) if known.any() else {}
        heard = lis.heard()
        entry = {k: m.get(k) for k in ("n", "accuracy", "bin_mae", "far_x_error", "majority_accuracy")}
        entry.update(summarise(heard))
        inside = [h for h, (_, _, _, ins, _) in zip(heard, frames) if ins]
        entry["beacon_on_goal_in_view"] = float(np.mean([h.on for h in inside])) if inside else None
        entry["heading_error_deg"] = error_stats(heading_errors(heard, far_x))
        # The curve scales every clip's own threshold (its orientation's and FOV's), so a view of
        # mixed photos (portrait photos as taken, portrait no-crossing views) plays at x 1 as the
        # bundle plays it; thresholds are quoted at the commonest camera of the view's photos.
        cams = Counter(lis.camera(i) for i in (np.flatnonzero(known) if known.any() else range(len(lis.clips))))
        t0 = float(engine.decision_config(*cams.most_common(1)[0][0]).threshold)
        curve = [{"threshold": t0 * c["scale"], **c} for c in lis.risk_coverage(scales=GATE_SCALES)]
        entry.update(bundle_threshold=t0, risk_coverage=curve, best_threshold_here=choose_threshold(curve),
                     orientations=dict(Counter(o for o, _ in cams.elements())),   # of the photos with a crossing
                     camera_fov_deg={f"{f:g}": n for f, n in sorted(Counter(round(f, 1) for _, f in cams.elements()
                                                                            if f is not None).items())})
        plot_risk_coverage(curve, t0, out / ("risk_coverage.png" if name == "landscape" else f"risk_coverage_{name}.png"),
                           f"{cfg.split}, {name}: what the user hears ({len(lis.clips)} frames)")
        result[name] = entry
    if cfg.scan_dps and (scan := _listen_scans(cfg, engine, part)):
        result["scan"] = scan
    return result


def _bundle_eval_out(bundle: Path, split: str) -> Path:
    """Where a bundle's evaluation goes without ``--out``: ``BUNDLE/eval_SPLIT``, except for a bundle
    shipped inside the package (the embedded default), which is never written into:
    ``runs/<bundle name>/eval_SPLIT`` under the working folder."""
    package = Path(__file__).resolve().parents[1]
    if bundle.resolve().is_relative_to(package):
        return Path("runs") / bundle.resolve().name / f"eval_{split}"
    return bundle / f"eval_{split}"


def evaluate(cfg: EvalConfig) -> tuple[Path, dict]:
    """Run the evaluation; returns (output folder, metrics dict)."""
    from .metrics import compute_metrics

    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    part = _split(cfg)
    policy = None
    if cfg.run is not None:
        probs, info, policy = _eval_checkpoint(cfg, part)
        n_actions, majority = policy.n_actions, policy.config.majority_action
        default_out = run_checkpoint(cfg.run).parent.parent / f"eval_{cfg.split}"
    else:
        probs, info, bundle = _eval_bundle(cfg, part)
        n_actions, majority = int(bundle.actions.n), bundle.training.get("majority_action")
        default_out = _bundle_eval_out(Path(cfg.bundle), cfg.split)
    if majority == 0:   # runs from before the baseline excluded unknown: the eval labels' majority
        majority = None
    grouped = cfg.actions is not None and cfg.actions != n_actions
    if grouped:  # a coarser action's probability is the sum over its strips
        if n_actions != 13:
            raise ConfigError(f"Invalid --actions {cfg.actions}: only a 13-action model can be scored in a coarser "
                              f"space; this one has {n_actions}")
        space = get_space(cfg.actions)
        probs = space.bin_probs_to_action_probs(probs)
        majority = None if majority is None else space.bin_to_action(int(majority))
        n_actions = cfg.actions
        info["grouped_from"] = 13
        default_out = default_out.with_name(f"{default_out.name}_{n_actions}")
    labels = get_space(n_actions).bins_to_actions(part.labels())
    m = compute_metrics(probs, labels, n_actions, part.far_x(), majority=majority)
    if cfg.bundle is not None and not grouped:  # the bundle's conformal threshold is for its own actions
        m["conformal"] = _bundle_conformal(bundle, probs, labels)
    m.update({"split": cfg.split, "data": str(cfg.data), "seed": cfg.seed, **info})
    out = Path(cfg.out) if cfg.out else default_out
    out.mkdir(parents=True, exist_ok=True)
    if cfg.bundle is not None and cfg.listen and not grouped:
        m["listen"] = listen_bundle(cfg, out)
    atomic_write_text(out / "metrics.json", json.dumps(m, indent=1, allow_nan=True))
    plot_confusion(np.array(m["confusion"]), m["names"], out / "confusion_matrix.png",
                   f"{cfg.split}: accuracy {m['accuracy']:.3f} (majority {m['majority_accuracy']:.3f})")
    plot_reliability(m["reliability"], m["ece"], out / "reliability.png")
    if cfg.examples:
        pred = probs.argmax(1)
        idx = _example_indices(pred, labels, cfg.examples)
        images = [load_frame(part.image_path(part.rows[i]), part.rows[i].flags) for i in idx]
        maps = activation_maps(policy, images, pred[idx]) if policy is not None and not grouped else [None] * len(idx)
        plot_examples(images, probs[idx], labels[idx], n_actions, maps, out / "examples.png")
    return out, m
