"""Aggregated data (the ``D`` of Algorithm 4.1), the per-episode trace the loop records, the
labels an aggregation picks from it and the episode context the strategies share."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Aggregate:
    """Growing training set. ``obs``: list of H x W x 3 uint8 frames; ``labels``: int actions or
    float vectors; ``weights``: sample weights (>= 0); ``episodes``/``steps``: where each came
    from (1-based episode, 0-based step); ``self_labelled``: True for the learner's own labels."""

    obs: list = field(default_factory=list)
    labels: list = field(default_factory=list)
    weights: list = field(default_factory=list)
    episodes: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    self_labelled: list = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.labels)

    def add(self, obs: np.ndarray, label, weight: float, episode: int, step: int, self_label: bool) -> None:
        self.obs.append(np.asarray(obs))
        self.labels.append(label)
        self.weights.append(float(weight))
        self.episodes.append(int(episode))
        self.steps.append(int(step))
        self.self_labelled.append(bool(self_label))

    def arrays(self, episode: int | None = None) -> dict[str, np.ndarray]:
        """Stacked arrays (all, or one episode's): obs N x H x W x 3, labels N[, d], weights N, ..."""
        idx = [k for k, e in enumerate(self.episodes) if episode is None or e == episode]
        if not idx:
            return {}
        return {
            "obs": np.stack([self.obs[k] for k in idx]),
            "labels": np.asarray([self.labels[k] for k in idx]),
            "weights": np.asarray([self.weights[k] for k in idx], dtype=np.float32),
            "episodes": np.asarray([self.episodes[k] for k in idx], dtype=np.int64),
            "steps": np.asarray([self.steps[k] for k in idx], dtype=np.int64),
            "self_labelled": np.asarray([self.self_labelled[k] for k in idx], dtype=bool),
        }

    def save_episode(self, path: Path, episode: int) -> None:
        """Write one episode's samples to ``path`` (compressed npz, atomic)."""
        from crossing_assist.fileio import atomic_path

        arrs = self.arrays(episode) or {"empty": np.zeros(0)}
        with atomic_path(path) as tmp:
            np.savez_compressed(tmp, **arrs)

    def load_episode(self, path: Path) -> None:
        """Append the samples of an npz written by :meth:`save_episode`."""
        with np.load(path) as z:
            if "empty" in z.files:
                return
            a = {k: z[k] for k in z.files}  # each z[k] decompresses the whole array: read each once
        for k in range(len(a["labels"])):
            lab = a["labels"][k]
            self.add(a["obs"][k], lab.item() if lab.ndim == 0 else lab, float(a["weights"][k]),
                     int(a["episodes"][k]), int(a["steps"][k]), bool(a["self_labelled"][k]))


@dataclass
class Step:
    """One step of an episode as the loop saw it. ``expert_action`` is None when the expert
    gave none; ``actor`` is ``expert``/``learner``/``explorer``; ``reward`` excludes the
    out-of-bounds penalty, which ``out_of_bounds`` flags."""

    t: int
    obs: np.ndarray
    expert_action: object
    u_expert: float
    learner_action: object
    u_learner: float
    actor: str
    action: object
    reward: float
    out_of_bounds: bool
    expert_acted: bool


@dataclass(frozen=True)
class Label:
    """One sample an aggregation adds to ``D``: the trace index ``index`` of its state, the
    ``action`` it is labelled with, its sample ``weight`` (>= 0) and whether the label is the
    learner's own (``self_labelled``, UPMS-SL) rather than the expert's."""

    index: int
    action: object
    weight: float = 1.0
    self_labelled: bool = False


@dataclass
class EpisodeContext:
    """What the strategies of one episode share, created by the loop before the episode.

    ``i``: episode (1-based); ``horizon``: steps. Written by a strategy, read by another:
    ``switch_time`` (0-based step; AggreVaTe's sampling draws it, its aggregation labels from
    it on; None: no switch this episode), ``cost_to_go`` (the aggregation's cost-to-go of the
    explored action, reported by the loop; None: none computed)."""

    i: int
    horizon: int
    switch_time: int | None = None
    cost_to_go: float | None = None
