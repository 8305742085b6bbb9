"""What is aggregated: the labels an episode adds to ``D``.

``select(trace, i, sampling) -> list of (step index, label, weight, self_labelled)``:

* :class:`ExpertLabels` ``("all")`` - the expert's action at every step it answered
  (DAgger-style: the expert labels the states the mixture visits);
* :class:`ExpertLabels` ``("acting")`` - only where the expert acted (UPMS, HG-DAgger,
  ThriftyDAgger: the expert is asked only when it takes control);
* :class:`ExpertLabels` ``("block", block)`` - Forward Training: the expert's labels in the
  time block trained this episode;
* :class:`SelfLabelling` - a base rule plus the learner's own action at every step that
  got no expert label (UPMS-SL);
* :class:`CostToGo` - AggreVaTe: the expert's labels from the switch time on, the explored
  state weighted by ``1 + min(w_max, max(0, -Q) / scale)`` where ``Q`` is the cost-to-go
  (the sum of rewards from the switch to the end of the episode, or to going out of bounds).
"""

from __future__ import annotations

from .data import Step
from .mixing import EXPERT


class Aggregation:
    name = "aggregation"

    def select(self, trace: list[Step], i: int, sampling) -> list[tuple[int, object, float, bool]]:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}


class ExpertLabels(Aggregation):
    name = "expert-labels"

    def __init__(self, when: str = "all", block: int = 1):
        if when not in ("all", "acting", "block"):
            raise ValueError(f"Unknown aggregation rule: {when!r}; valid: all, acting, block")
        self.when, self.block = when, int(block)

    def select(self, trace, i, sampling):
        out = []
        for k, s in enumerate(trace):
            if s.expert_action is None:
                continue
            if self.when == "acting" and s.actor != EXPERT:
                continue
            if self.when == "block" and s.t // self.block != i - 1:
                continue
            out.append((k, s.expert_action, 1.0, False))
        return out


class SelfLabelling(Aggregation):
    """``base``'s labels, plus the learner's own action where the expert gave none."""

    name = "self-labelling"

    def __init__(self, base: Aggregation):
        self.base = base

    def select(self, trace, i, sampling):
        out = self.base.select(trace, i, sampling)
        labelled = {k for k, *_ in out}
        for k, s in enumerate(trace):
            if k not in labelled and s.learner_action is not None:
                out.append((k, s.learner_action, 1.0, True))
        return sorted(out, key=lambda r: r[0])

    def describe(self):
        return {"name": self.name, "base": self.base.describe()}


class CostToGo(Aggregation):
    name = "cost-to-go"

    def __init__(self, scale: float = 10.0, w_max: float = 4.0):
        self.scale, self.w_max = float(scale), float(w_max)
        self.last_cost_to_go: float | None = None

    def select(self, trace, i, sampling):
        ts = getattr(sampling, "switch_time", None)
        if ts is None:  # first episode: all expert
            self.last_cost_to_go = None
            return ExpertLabels("acting").select(trace, i, sampling)
        start = next((k for k, s in enumerate(trace) if s.t == ts), None)
        if start is None:
            self.last_cost_to_go = None
            return []
        q = 0.0
        for s in trace[start:]:
            if s.out_of_bounds:
                q -= self.scale * self.w_max  # the failure is the worst cost; -1000 stays excluded
                break
            q += s.reward
        self.last_cost_to_go = q
        w = 1.0 + min(self.w_max, max(0.0, -q) / self.scale)
        out = []
        for k in range(start, len(trace)):
            s = trace[k]
            if s.expert_action is not None and (k == start or s.actor == EXPERT):
                out.append((k, s.expert_action, w if k == start else 1.0, False))
        return out
