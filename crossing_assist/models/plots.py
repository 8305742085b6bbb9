"""Plots: training curves (``results.png``), and for evaluation the confusion matrix, reliability
diagram, example sheet with activation maps and risk-coverage curve.

Every figure is written atomically (temp file + ``os.replace``) with matplotlib's Agg backend.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..actions import N_BINS, get_space
from ..plotting import pyplot as _plt
from ..plotting import save_figure as _save


def plot_training(out: str | Path) -> Path:
    """``out/results.png`` from ``out/results.csv`` (a training run folder): train loss, and
    selection/val accuracy per epoch (a blank cell is a gap). Returns the image's path."""
    plt = _plt()
    out = Path(out)
    with open(out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    ep = [int(r["epoch"]) for r in rows]
    num = lambda k: [float(r[k]) if r[k] else np.nan for r in rows]  # noqa: E731
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.5))
    a.plot(ep, num("train_loss"))
    a.set(xlabel="epoch", ylabel="train loss", title="loss")
    for k, lab in (("sel_accuracy", "selection"), ("val_accuracy", "val")):
        b.plot(ep, num(k), label=lab)
    b.set(xlabel="epoch", ylabel="accuracy", title="accuracy")
    b.legend()
    fig.tight_layout()
    return _save(fig, out / "results.png")


def plot_confusion(conf: np.ndarray, names: list[str], path: Path, title: str = "") -> Path:
    """Rows = true action, columns = predicted, counts annotated, row-normalised colour."""
    plt = _plt()
    conf = np.asarray(conf)
    norm = conf / np.maximum(conf.sum(1, keepdims=True), 1)
    n = len(names)
    fig, ax = plt.subplots(figsize=(1.0 + 0.5 * n, 0.8 + 0.5 * n))
    ax.imshow(norm, cmap="Blues", vmin=0, vmax=1)
    for i in range(n):
        for j in range(n):
            if conf[i, j]:
                ax.text(j, i, str(conf[i, j]), ha="center", va="center", fontsize=7,
                        color="white" if norm[i, j] > 0.5 else "black")
    ax.set_xticks(range(n), names, rotation=90)
    ax.set_yticks(range(n), names)
    ax.set(xlabel="predicted action", ylabel="true action", title=title or "confusion matrix")
    fig.tight_layout()
    return _save(fig, path)


def plot_reliability(rel: dict, ece: float, path: Path) -> Path:
    """Accuracy vs confidence per bin, the diagonal, and the bin counts."""
    plt = _plt()
    edges = np.asarray(rel["edges"])
    centres = (edges[:-1] + edges[1:]) / 2
    acc = np.array([np.nan if v is None else v for v in rel["accuracy"]])
    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.bar(centres, np.nan_to_num(acc), width=edges[1] - edges[0], edgecolor="k", alpha=0.7, label="accuracy")
    ax.plot([0, 1], [0, 1], "r--", label="perfect calibration")
    ax.set(xlabel="confidence (max probability)", ylabel="accuracy", xlim=(0, 1), ylim=(0, 1),
           title=f"reliability (ECE {ece:.3f})")
    ax.legend(loc="upper left")
    fig.tight_layout()
    return _save(fig, path)


def plot_examples(images: list[np.ndarray], probs: np.ndarray, labels: np.ndarray, n_actions: int,
                  maps: list[np.ndarray | None], path: Path, cols: int = 4) -> Path:
    """A sheet of frames: true goal strip (green), top-3 predicted strips (red, alpha by rank),
    and the class activation map of the top action as a heat overlay.

    images: H x W x 3 uint8 each; probs: K x A; labels: (K,) actions; maps: per frame an
    h x w activation map of the predicted action (any size, resized here) or None.
    """
    plt = _plt()
    space = get_space(n_actions)
    k = len(images)
    rows = max(1, (k + cols - 1) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.4 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for i, (img, p, y, cam) in enumerate(zip(images, probs, labels, maps)):
        ax = axes.ravel()[i]
        h, w = img.shape[:2]
        ax.imshow(img)
        if cam is not None:
            cam = np.asarray(cam, dtype=np.float64)
            cam = (cam - cam.min()) / max(cam.max() - cam.min(), 1e-9)
            ax.imshow(cam, cmap="jet", alpha=0.35, extent=(0, w, h, 0), interpolation="bilinear")
        top = np.argsort(-p)[:3]
        for rank, a in enumerate(top):
            if a == 0:
                continue
            bins = space.action_bins(int(a))
            x0, x1 = (bins[0] - 1) * w / N_BINS, bins[-1] * w / N_BINS
            ax.axvspan(x0, x1, ymin=0.0, ymax=0.08, color="red", alpha=0.8 - 0.25 * rank)
        if y != 0:
            bins = space.action_bins(int(y))
            ax.axvspan((bins[0] - 1) * w / N_BINS, bins[-1] * w / N_BINS, ymin=0.92, ymax=1.0, color="lime", alpha=0.8)
        names = space.names
        ax.set_title(f"true {names[y]} | " + ", ".join(f"{names[a]} {p[a]:.2f}" for a in top), fontsize=7)
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
    fig.suptitle("green: true strip; red: top-3 predicted (darker = higher); heat: activation map of the top action",
                 fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def plot_risk_coverage(curve: list[dict], chosen: float | None, path: Path, title: str = "") -> Path:
    """Confidently-wrong rate against beacon-on rate as the gate's threshold sweeps; the
    bundle's threshold marked. Lower right is better."""
    plt = _plt()
    on = np.array([c["beacon_on"] or 0 for c in curve])
    wrong = np.array([c["confidently_wrong"] or 0 for c in curve])
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.plot(on, 100 * wrong, "o-", ms=3, label="gate threshold sweep")
    for c in curve:
        if chosen is not None and abs(c["threshold"] - chosen) < 1e-9:
            ax.plot([c["beacon_on"]], [100 * (c["confidently_wrong"] or 0)], "r*", ms=14,
                    label=f"bundle threshold {chosen:.3g}")
    ax.axhline(0.5, color="grey", ls="--", lw=1, label="target: 0.5 % confidently wrong")
    ax.set(xlabel="beacon on (frames with a crossing)", ylabel="confidently wrong (% of frames)",
           title=title or "risk-coverage")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)
