"""The training loop (one readable loop, top to bottom) for ``crossing-train``.

The backbone's first ``len(blocks) - unfreeze`` blocks are frozen: their output is computed
once per (frame, variant) and cached (:mod:`.cache`), so an epoch costs only the trainable
part. Frozen batch-norm statistics stay fixed (eval mode). Run folder::

    OUT/args.yaml  results.csv  results.png  weights/last.pt  weights/best.pt

``last.pt`` (written atomically at the end of every epoch) carries the optimizer state and
the best score so far, so ``--resume`` after a kill continues at the next epoch and the run
ends with the same number of epochs as an uninterrupted one.

Under ``torchrun`` (WORLD_SIZE > 1) the loop is DistributedDataParallel (:mod:`.distributed`):
each global batch is split across the ranks, rank 0 builds the feature cache and alone writes
the run folder.
"""

from __future__ import annotations

import csv
import io
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
import yaml
from tqdm import tqdm

from ..actions import N_BINS, UNKNOWN, get_space
from ..data_tools.manifest import Dataset, atomic_write_text, read_manifest
from ..fileio import sweep_orphans
from .backbones import create_backbone
from .cache import FeatureSet, compute_features, entry_lock
from .checkpoint import load_checkpoint, save_checkpoint
from .config import CLASS_WEIGHT_POWER, ConfigError, TrainConfig
from . import distributed
from .data import make_variants
from .heads import create_head
from .metrics import compute_metrics
from .plots import plot_training
from .policy import Policy, policy_config

RESULT_FIELDS = ("epoch", "train_loss", "sel_accuracy", "sel_bin_mae", "sel_nll",
                 "val_accuracy", "val_bin_mae", "val_nll", "seconds")


@dataclass(frozen=True)
class Split:
    """Cached samples of one set, labels already mapped to actions."""

    feats: torch.Tensor          # M x C x h x w float16
    actions: np.ndarray          # (M,) int64
    far_x: np.ndarray            # (M,) float64
    window: torch.Tensor         # M x 2 float32: the frame's extent on the canvas


def _check_sets(cfg: TrainConfig, ds: Dataset) -> tuple[Dataset, Dataset | None]:
    """(the whole train split, val or None), checking holdout sources and the selection set."""
    train = ds.split("train")
    hold = set(cfg.holdout)
    unknown = hold - {r.source for r in train.rows}
    if unknown:
        raise ConfigError(f"Invalid holdout: {', '.join(sorted(unknown))} not among train sources "
                          f"({', '.join(train.sources())})")
    if not any(r.source not in hold for r in train.rows):
        raise ConfigError(f"Invalid data: {ds.root} has no train rows (after holding out {sorted(hold)})")
    val = ds.split("val")
    val = val if len(val) else None
    if cfg.select_on == "val" and val is None:
        raise ConfigError(f"Invalid select_on val: {ds.root} has no val rows; use --select-on last or --holdout")
    return train, val


def _take(split: Split, mask: np.ndarray) -> Split:
    idx = torch.from_numpy(np.flatnonzero(mask))
    return Split(split.feats[idx], split.actions[mask], split.far_x[mask], split.window[idx])


def _hold_out(full: Split, fs: FeatureSet, train_ds: Dataset, hold: tuple[str, ...]) -> tuple[Split, Split | None]:
    """Split the cached train samples by source: (training samples, held-out identity frames).

    The whole train split is cached once; holding sources out is a mask, never a new cache."""
    if not hold:
        return full, None
    held_row = np.array([r.source in hold for r in train_ds.rows])[fs.row]
    return _take(full, ~held_row), _take(full, held_row & (fs.variant == 0))


def _to_split(fs: FeatureSet, n_actions: int) -> Split:
    feats = torch.from_numpy(np.array(fs.feats))  # copy into memory (the file is read-only)
    return Split(feats, get_space(n_actions).bins_to_actions(fs.labels), fs.far_x,
                 torch.from_numpy(np.asarray(fs.window, np.float32)))


def _concat(a: Split, b: Split) -> Split:
    if a.feats.shape[1:] != b.feats.shape[1:]:
        raise ConfigError(f"Invalid extra data: feature shapes differ ({tuple(a.feats.shape[1:])} vs {tuple(b.feats.shape[1:])})")
    return Split(torch.cat([a.feats, b.feats]), np.concatenate([a.actions, b.actions]),
                 np.concatenate([a.far_x, b.far_x]), torch.cat([a.window, b.window]))


def _targets(actions: torch.Tensor, n: int, smoothing: float, far_x: torch.Tensor | None = None,
             soft_x: float = 0.0) -> torch.Tensor:
    """Soft targets: 1 - s on the true action, s shared by its known neighbours (a +- 1).

    With ``soft_x > 0`` a frame whose goal position is known gets instead the mass that a Gaussian
    around ``far_x`` (sd ``soft_x`` strip widths) puts in each strip, the edge strips reaching past
    the frame, summed into actions: a goal near a strip edge leans toward the strip across it,
    one in a strip's middle keeps most of the mass (sd 0.4: 79 %, about smoothing 0.2)."""
    t = F.one_hot(actions, n).float()
    if smoothing > 0:
        left = torch.where(actions > 1, actions - 1, actions)
        right = torch.where((actions > 0) & (actions < n - 1), actions + 1, actions)
        known = (actions != UNKNOWN).float()[:, None]
        nb = 0.5 * (F.one_hot(left, n).float() + F.one_hot(right, n).float())
        t = t * (1 - smoothing * known) + smoothing * known * nb
    if soft_x <= 0 or far_x is None:
        return t
    use = (actions != UNKNOWN) & ~torch.isnan(far_x)
    x = torch.nan_to_num(far_x.float(), nan=0.5)[:, None]
    edges = torch.arange(1, N_BINS, dtype=torch.float32) / N_BINS
    cdf = torch.special.ndtr((edges - x) * (N_BINS / soft_x))
    cdf = torch.cat([torch.zeros_like(x), cdf, torch.ones_like(x)], 1)
    strips = torch.tensor(get_space(n).lookup[1:])
    soft = torch.zeros(len(actions), n).index_add_(1, strips, cdf[:, 1:] - cdf[:, :-1])
    return torch.where(use[:, None], soft, t)


def far_x_loss(logits: torch.Tensor, far_x: torch.Tensor, n_actions: int) -> torch.Tensor:
    """Mean |E[x] - far_x| (fraction of width) over frames with a known goal, where E[x] is
    the mean action centre under the softmax restricted to known actions; 0 if none known."""
    space = get_space(n_actions)
    centres = torch.tensor([space.action_center_x(a) for a in range(1, n_actions)], dtype=logits.dtype)
    ex = (logits[:, 1:].softmax(-1) * centres).sum(-1)
    known = ~torch.isnan(far_x)
    if not bool(known.any()):
        return logits.sum() * 0.0
    return (ex[known] - far_x[known]).abs().mean()


def _class_weights(actions: np.ndarray, n: int, power: float = 1.0) -> torch.Tensor:
    """Inverse-frequency weights to ``power`` (``config.CLASS_WEIGHT_POWER``), mean 1 over present
    classes; absent classes 0."""
    counts = np.bincount(actions, minlength=n).astype(np.float64)
    w = np.where(counts > 0, np.maximum(counts, 1) ** -power, 0.0)
    w *= (counts > 0).sum() / max(w.sum(), 1e-12)
    return torch.tensor(w, dtype=torch.float32)


def _epoch_order(train: Split, cfg: TrainConfig, epoch: int) -> np.ndarray:
    """Sample order of one epoch; deterministic in (seed, epoch) so a resumed run matches."""
    rng = np.random.default_rng([cfg.seed, epoch])
    m = len(train.actions)
    if cfg.balance != "sampler":
        return rng.permutation(m)
    counts = np.bincount(train.actions)
    w = 1.0 / counts[train.actions]
    return rng.choice(m, size=m, replace=True, p=w / w.sum())


@torch.no_grad()
def predict_split(policy: Policy, split: Split, start: int, batch_size: int = 256,
                  samples: int = 1) -> np.ndarray:
    """Mean softmax (N x A) over ``samples`` (MC dropout when samples > 1) from cached feats."""
    policy.eval()
    out = []
    for i in range(0, len(split.actions), batch_size):
        x = split.feats[i:i + batch_size].float()
        logits = policy.forward_from(x, start, samples=samples, mc=samples > 1, window=split.window[i:i + batch_size])
        out.append(logits.softmax(-1).mean(0))
    return torch.cat(out).numpy()


def _train_mode(policy: Policy, start: int) -> None:
    """Head and unfrozen blocks train; every batch norm keeps its statistics (eval mode)."""
    policy.train()
    for m in policy.modules():
        if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
            m.eval()
    for i, block in enumerate(policy.backbone.blocks):
        block.requires_grad_(i >= start)


def _build(cfg: TrainConfig) -> tuple[Policy, int]:
    backbone = create_backbone(cfg.backbone, weights=cfg.weights, feature_stride=cfg.feature_stride)
    n_blocks = len(backbone.blocks)
    if cfg.unfreeze > n_blocks:
        raise ConfigError(f"Invalid unfreeze {cfg.unfreeze}: {cfg.backbone} has {n_blocks} blocks")
    if backbone.skip is not None and n_blocks - cfg.unfreeze > backbone.skip:
        raise ConfigError(f"Invalid unfreeze {cfg.unfreeze} with feature stride 16: the skip reads block "
                          f"{backbone.skip}, so unfreeze >= {n_blocks - backbone.skip}")
    kind = "thesis_fc" if cfg.head == "thesis" and cfg.backbone == "resnet50" else cfg.head
    head = create_head(kind, backbone.num_features, cfg.actions, p=cfg.p)
    conf = policy_config(backbone, kind, cfg.actions, p=cfg.p, input_size=cfg.input_size, fov_deg=cfg.fov_deg,
                         frozen_blocks=n_blocks - cfg.unfreeze, data=str(cfg.data), fit=cfg.fit,
                         feature_stride=backbone.facts.stride if backbone.skip is not None else None)
    return Policy(backbone, head, conf), n_blocks - cfg.unfreeze


def _optimizer(cfg: TrainConfig, policy: Policy) -> torch.optim.Optimizer:
    params = [p for p in policy.parameters() if p.requires_grad]
    if cfg.optimizer == "rmsprop":
        return torch.optim.RMSprop(params, lr=cfg.lr, alpha=0.9, eps=1e-8, weight_decay=cfg.weight_decay)
    return torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay)


def _set_lr(opt: torch.optim.Optimizer, cfg: TrainConfig, epoch: int, step: int, steps: int) -> None:
    """The learning rate of step ``step`` (of ``steps``) in ``epoch``: ``cfg.lr`` throughout, or
    (cosine) falling from ``cfg.lr`` to 0 over all ``cfg.epochs`` epochs. It is a function of the
    position alone, so a resumed run continues on the same curve (a larger ``--epochs`` stretches it)."""
    lr = cfg.lr
    if cfg.lr_schedule == "cosine":
        done = (epoch - 1 + step / max(steps, 1)) / cfg.epochs
        lr = 0.5 * cfg.lr * (1.0 + math.cos(math.pi * done))
    for group in opt.param_groups:
        group["lr"] = lr


def _score(m: dict | None) -> tuple[float, float]:
    """Higher is better: accuracy, then lower bin MAE."""
    if m is None:
        return (0.0, 0.0)
    mae = m["bin_mae"]
    return (m["accuracy"], -(mae if not math.isnan(mae) else 99.0))


def _write_results(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=RESULT_FIELDS)
    w.writeheader()
    w.writerows(rows)
    atomic_write_text(path, buf.getvalue())


def _read_results(path: Path, upto: int) -> list[dict]:
    if not path.is_file():
        return []
    with open(path, newline="") as fh:
        return [r for r in csv.DictReader(fh) if int(r["epoch"]) <= upto]


def _metrics_or_none(policy: Policy, split: Split | None, start: int, n: int, majority: int) -> dict | None:
    if split is None:
        return None
    return compute_metrics(predict_split(policy, split, start), split.actions, n, split.far_x, majority=majority)


def _fmt(v: float | None) -> str:
    return "" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.4f}"


def train(cfg: TrainConfig, *, resume: bool = False) -> Path:
    """Train per ``cfg`` into ``cfg.out``; returns the run folder. Raises ConfigError /
    ManifestError / CheckpointError / BackboneError with one clear line on bad input. One run
    writes a folder at a time: a second one started on the same ``--out`` (both would exit 0
    with the files of two runs mixed) is refused while the first runs (an advisory lock,
    ``OUT/.run.lock``, released by the system if the first is killed)."""
    ctx = distributed.setup()       # rank 0 of 1 unless launched by torchrun
    if not ctx.main:                # torchrun: rank 0 holds the lock for all ranks
        return _train(cfg, ctx, resume=resume)
    with entry_lock(cfg.out, ".run", wait=False) as held:
        if not held:
            raise ConfigError(f"Invalid --out: another crossing-train is writing {cfg.out}; wait for it to end "
                              "or pick a new --out")
        return _train(cfg, ctx, resume=resume)


def _train(cfg: TrainConfig, ctx: distributed.Context, *, resume: bool) -> Path:
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)     # head initialisation (the run's own generator state)
    out = Path(cfg.out)
    last_path, best_path = out / "weights" / "last.pt", out / "weights" / "best.pt"
    for folder in (out, out / "weights") if ctx.main else ():  # temporary files of a killed run
        sweep_orphans(folder)
    state = None
    if resume:
        if not last_path.is_file():
            raise ConfigError(f"Invalid --resume: {last_path} not found (start without --resume)")
        state = load_checkpoint(last_path)
        cfg = _resumed(cfg, state, last_path)
    elif last_path.is_file():
        raise ConfigError(f"Invalid --out: {out} already holds a run; pass --resume or pick a new --out")
    ds = read_manifest(cfg.data)
    train_ds, val_ds = _check_sets(cfg, ds)
    if ctx.main and (msg := fov_mismatch(ds, cfg.fov_deg)):
        print(f"warning: {msg}", file=sys.stderr, flush=True)
    policy, start = _build(cfg)
    size = policy.config.input_size
    variants = make_variants(cfg.mirror, cfg.yaw, cfg.field, cfg.field_without, cfg.field_zoom)
    cache = Path(cfg.cache_dir)
    fs = lambda d, v, name, wait=True: compute_features(  # noqa: E731
        policy.backbone, start, d, size, v, cfg.fov_deg, cache, progress=cfg.progress, desc=f"features {name}",
        fit=cfg.fit, seed=cfg.seed, wait=wait)
    extras = [ex for ex in (read_manifest(e).split("train") for e in cfg.extra_data) if len(ex)]
    entries = [(train_ds, variants, "train"), *((ex, variants, f"train {Path(ex.root).name}") for ex in extras),
               *([(val_ds, make_variants(False), "val")] if val_ds is not None else [])]
    with distributed.main_first(ctx):  # rank 0 builds the cache, the other ranks then read it
        # runs side by side on one cache (--cv-jobs): each first builds the entries no other run is
        # building, then waits for the rest
        built = [fs(*e, wait=False) for e in entries]
        train_fs, *extra_fs = [b if b is not None else fs(*e) for b, e in zip(built, entries)]
        val_fs = extra_fs.pop() if val_ds is not None else None
        tr, held = _hold_out(_to_split(train_fs, cfg.actions), train_fs, train_ds, cfg.holdout)
        n_extra = 0
        for ex, ex_fs in zip(extras, extra_fs):  # cached per folder, so adding data never recomputes the main set
            ex_split, _ = _hold_out(_to_split(ex_fs, cfg.actions), ex_fs, ex, cfg.holdout)  # held-out sources stay out
            tr = _concat(tr, ex_split)
            n_extra += int(sum(r.source not in cfg.holdout for r in ex.rows))
        val = _to_split(val_fs, cfg.actions) if val_fs is not None else None
    sel = val if cfg.select_on == "val" else held
    # the majority-class baseline is the most frequent *direction* (unknown negatives would make a
    # baseline that is right on no crossing photo); all-unknown training data keeps unknown
    counts = np.bincount(tr.actions, minlength=cfg.actions)
    majority = int(counts[1:].argmax()) + 1 if counts[1:].any() else 0
    sizes = {"train_split": int(len(train_ds)), "extra_train": n_extra,
             "train_samples": int(len(tr.actions)), "val": int(len(val_ds or ())),
             "holdout_frames": int(len(held.actions)) if held is not None else 0}
    policy.config = replace(policy.config, counts=sizes, majority_action=majority)
    _train_mode(policy, start)
    opt = _optimizer(cfg, policy)
    first_epoch, best = 1, None
    if state is not None:
        policy.load_state_dict(state["state_dict"])
        opt.load_state_dict(state["optimizer"])
        first_epoch = int(state["epoch"]) + 1
        best = state.get("best_score")
    if ctx.main:
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "args.yaml", yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    rows = _read_results(out / "results.csv", first_epoch - 1)
    power = CLASS_WEIGHT_POWER.get(cfg.balance)
    weights = _class_weights(tr.actions, cfg.actions, power) if power else None
    fwd = distributed.wrap(policy, start, ctx)
    bar = tqdm(range(first_epoch, cfg.epochs + 1), desc="train", disable=not (cfg.progress and ctx.main),
               initial=first_epoch - 1, total=cfg.epochs, unit="epoch")
    for epoch in bar:
        t0 = time.time()
        loss = _run_epoch(policy, opt, tr, start, cfg, epoch, weights, fwd, ctx)
        if not ctx.main:  # only rank 0 evaluates and writes; the others go on to the next epoch
            continue
        m_sel = _metrics_or_none(policy, sel, start, cfg.actions, majority)
        m_val = m_sel if sel is val else _metrics_or_none(policy, val, start, cfg.actions, majority)
        row = {"epoch": epoch, "train_loss": f"{loss:.5f}", "seconds": f"{time.time() - t0:.2f}"}
        for prefix, m in (("sel", m_sel), ("val", m_val)):
            for k in ("accuracy", "bin_mae", "nll"):
                row[f"{prefix}_{k}"] = _fmt(m[k]) if m else ""
        rows.append(row)
        is_best = cfg.select_on == "last" or best is None or list(_score(m_sel)) > list(best)
        if is_best:
            best = list(_score(m_sel))
            save_checkpoint(best_path, policy, {"metrics": {"selection": _slim(m_sel), "val": _slim(m_val)},
                                                "epoch": epoch, "train_config": cfg.to_dict()})
        # results.csv before last.pt: a kill between them leaves a row past last.pt's epoch, which
        # --resume drops and recomputes (the other order would lose the row for good)
        _write_results(out / "results.csv", rows)
        save_checkpoint(last_path, policy, {"metrics": {"selection": _slim(m_sel), "val": _slim(m_val)},
                                            "epoch": epoch, "train_config": cfg.to_dict(),
                                            "optimizer": opt.state_dict(), "best_score": best})
        bar.set_postfix(loss=row["train_loss"], acc=row["sel_accuracy"], mae=row["sel_bin_mae"])
    if ctx.main:
        plot_training(out)
    distributed.barrier(ctx)  # every rank returns once the run folder is complete
    return out


# Options a resumed run may change: how it runs, not what it computes (epochs may only grow).
RESUME_FREE = ("progress", "threads", "cache_dir")


def _same(key: str, a, b) -> bool:
    if key == "data":
        return Path(a).resolve() == Path(b).resolve()
    if key == "extra_data":
        return [Path(x).resolve() for x in a] == [Path(x).resolve() for x in b]
    return a == b


def _resumed(cfg: TrainConfig, state: dict, last_path: Path) -> TrainConfig:
    """``cfg`` checked against the run being resumed: every option must match the saved one
    except those in :data:`RESUME_FREE`, and ``epochs`` may grow (an explicit extension).
    Raises ConfigError naming every difference."""
    saved = TrainConfig.from_dict({**state["train_config"], "progress": cfg.progress})
    mine, theirs = cfg.to_dict(), saved.to_dict()
    diffs = [f"--{k.replace('_', '-')} {mine[k]!r} (run: {theirs[k]!r})" for k in mine
             if k not in RESUME_FREE + ("epochs", "out") and not _same(k, mine[k], theirs[k])]
    if diffs:
        raise ConfigError(f"Invalid --resume: options differ from the run in {cfg.out}: {'; '.join(diffs)}; "
                          "drop them or start a new --out")
    done = int(state["epoch"])
    if cfg.epochs < done:
        raise ConfigError(f"Invalid --resume --epochs {cfg.epochs}: {last_path} has already trained {done} epochs; "
                          f"pass --epochs >= {done}")
    return TrainConfig.from_dict({**theirs, **{k: mine[k] for k in RESUME_FREE + ("epochs",)}})


def resume_config(cfg: TrainConfig, given: set[str]) -> TrainConfig:
    """The config of the run in ``cfg.out`` with only the options named in ``given`` (as typed
    on the command line: ``four_three``, ``quiet`` map to ``input_size``, ``progress``) taken
    from ``cfg``; :func:`train` then refuses any that changes what the run computes."""
    last_path = Path(cfg.out) / "weights" / "last.pt"
    if not last_path.is_file():
        raise ConfigError(f"Invalid --resume: {last_path} not found (start without --resume)")
    alias = {"four_three": "input_size", "quiet": "progress"}
    names = {alias.get(g, g) for g in given}
    saved = load_checkpoint(last_path)["train_config"]
    mine = cfg.to_dict()
    keep = names | {"out", "progress", "threads"}
    return TrainConfig.from_dict({**saved, **{k: v for k, v in mine.items() if k in keep}})


def fov_mismatch(ds: Dataset, fov_deg: float) -> str | None:
    """A line when rows' ``fov=`` flags (their camera, from ``crossing-data frames --fov``) differ
    from ``--fov`` by over a degree: the yaw views and the far point's heading assume ``--fov``."""
    from ..data_tools.images import ImageError, frame_fov
    from ..geometry import SAME_CAMERA_DEG

    seen: dict[float, int] = {}
    for r in ds.rows:
        try:
            f = frame_fov(r.flags)
        except ImageError as exc:
            raise ConfigError(f"{ds.image_path(r)}: {exc}") from None
        if f is not None and abs(f - fov_deg) > SAME_CAMERA_DEG:
            seen[f] = seen.get(f, 0) + 1
    if not seen:
        return None
    cams = ", ".join(f"{n} at {f:g} deg" for f, n in sorted(seen.items()))
    return (f"{sum(seen.values())} frames were taken by a camera other than --fov {fov_deg:g} ({cams}): their yaw "
            f"views assume --fov; train on one camera's frames with its --fov")


def trained_epochs(out: Path) -> int:
    """Epochs the run in ``out`` has finished (from weights/last.pt), 0 when none."""
    path = Path(out) / "weights" / "last.pt"
    return int(load_checkpoint(path)["epoch"]) if path.is_file() else 0


def _slim(m: dict | None) -> dict:
    keys = ("n", "accuracy", "bin_mae", "balanced_accuracy", "top3_accuracy", "nll", "ece",
            "majority_accuracy", "majority_bin_mae", "far_x_error")
    return {k: m[k] for k in keys if m and k in m}


def _run_epoch(policy: Policy, opt: torch.optim.Optimizer, tr: Split, start: int, cfg: TrainConfig,
               epoch: int, weights: torch.Tensor | None, fwd: torch.nn.Module | None = None,
               ctx: distributed.Context = distributed.Context()) -> float:
    """One pass over the cached training samples; returns the mean loss."""
    _train_mode(policy, start)
    torch.manual_seed(cfg.seed * 100003 + epoch + 7919 * ctx.rank)  # dropout masks, reproducible on resume
    order = _epoch_order(tr, cfg, epoch)
    if ctx.active:
        return _run_epoch_ddp(opt, tr, cfg, epoch, weights, fwd, ctx, order)
    total, count = 0.0, 0
    steps = range(0, len(order), cfg.batch_size)
    for step, i in enumerate(tqdm(steps, desc=f"epoch {epoch}", leave=False, disable=not cfg.progress)):
        _set_lr(opt, cfg, epoch, step, len(steps))
        idx = torch.from_numpy(order[i:i + cfg.batch_size])
        x = tr.feats[idx].float()
        y = torch.from_numpy(tr.actions[idx.numpy()])
        logits = policy.forward_from(x, start, samples=1, mc=True, window=tr.window[idx])[0]
        fx = torch.from_numpy(tr.far_x[idx.numpy()]).float()
        target = _targets(y, cfg.actions, cfg.smoothing, fx, cfg.soft_x)
        logp = logits.log_softmax(-1)
        per = -(target * (logp if weights is None else logp * weights)).sum(-1)
        loss = per.mean()
        if cfg.aux_x > 0:
            loss = loss + cfg.aux_x * far_x_loss(logits, fx, cfg.actions)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        total += float(loss.detach()) * len(idx)
        count += len(idx)
    return total / max(count, 1)


def _run_epoch_ddp(opt: torch.optim.Optimizer, tr: Split, cfg: TrainConfig, epoch: int, weights: torch.Tensor | None,
                   fwd: torch.nn.Module, ctx: distributed.Context, order: np.ndarray) -> float:
    """:func:`_run_epoch` on this rank's part of every global batch. Each rank's loss is its share
    of the global batch's loss (sums over its samples divided by the global counts), times the
    world size because DDP averages the gradients: the step equals the one-process step."""
    total = 0.0
    starts = range(0, len(order), cfg.batch_size)
    for step, i in enumerate(starts):
        _set_lr(opt, cfg, epoch, step, len(starts))
        batch = order[i:i + cfg.batch_size]
        part, keep_np = distributed.rank_slice(batch, ctx)
        idx, keep = torch.from_numpy(part), torch.from_numpy(keep_np)
        logits = fwd(tr.feats[idx].float(), tr.window[idx])
        target = _targets(torch.from_numpy(tr.actions[part]), cfg.actions, cfg.smoothing,
                          torch.from_numpy(tr.far_x[part]).float(), cfg.soft_x)
        logp = logits.log_softmax(-1)
        per = -(target * (logp if weights is None else logp * weights)).sum(-1)
        loss = (per * keep).sum() / len(batch)
        if cfg.aux_x > 0:
            fx = torch.from_numpy(np.where(keep_np > 0, tr.far_x[part], np.nan)).float()
            mine, known = int((~torch.isnan(fx)).sum()), int((~np.isnan(tr.far_x[batch])).sum())
            loss = loss + cfg.aux_x * far_x_loss(logits, fx, cfg.actions) * (mine / max(known, 1))
        opt.zero_grad(set_to_none=True)
        (loss * ctx.world).backward()
        opt.step()
        total += float(loss.detach()) * len(batch)
    return distributed.all_sum(ctx, total) / max(len(order), 1)

