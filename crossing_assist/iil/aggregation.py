"""What is aggregated: the labels an episode adds to ``D``.

``select(trace, ctx) -> list of`` :class:`~crossing_assist.iil.data.Label` (trace index,
action, weight, self-labelled), in trace order; ``ctx`` is the episode's
:class:`~crossing_assist.iil.data.EpisodeContext`:

* :class:`ExpertLabels` ``("all")`` - the expert's action at every step it answered
  (DAgger-style: the expert labels the states the mixture visits);
* :class:`ExpertLabels` ``("acting")`` - only where the expert acted (UPMS, HG-DAgger,
  ThriftyDAgger: the expert is asked only when it takes control);
* :class:`ExpertLabels` ``("block", block)`` - Forward Training: the expert's labels in the
  time block trained this episode;
* :class:`SelfLabelling` - a base rule plus the learner's own action at every step that
  got no expert label (UPMS-SL);
* :class:`CostToGo` - AggreVaTe: the expert's labels from the switch time
  (``ctx.switch_time``, drawn by the sampling) on, the explored state weighted by
  ``1 + min(w_max, max(0, -Q) / scale)`` where ``Q`` is the cost-to-go (the sum of rewards from
  the switch to the end of the episode, or to going out of bounds), written to
  ``ctx.cost_to_go``.
"""

from __future__ import annotations

from .data import EpisodeContext, Label, Step
from .mixing import EXPERT


class Aggregation:
    name = "aggregation"

    def select(self, trace: list[Step], ctx: EpisodeContext) -> list[Label]:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}


class ExpertLabels(Aggregation):
    name = "expert-labels"

    def __init__(self, when: str = "all", block: int = 1):
        if when not in ("all", "acting", "block"):
            raise ValueError(f"Unknown aggregation rule: {when!r}; valid: all, acting, block")
        self.when, self.block = when, int(block)

    def select(self, trace, ctx):
        out = []
        for k, s in enumerate(trace):
            if s.expert_action is None:
                continue
            if self.when == "acting" and s.actor != EXPERT:
                continue
            if self.when == "block" and s.t // self.block != ctx.i - 1:
                continue
            out.append(Label(k, s.expert_action))
        return out


class SelfLabelling(Aggregation):
    """``base``'s labels, plus the learner's own action where the expert gave none."""

    name = "self-labelling"

    def __init__(self, base: Aggregation):
        self.base = base

    def select(self, trace, ctx):
        out = self.base.select(trace, ctx)
        labelled = {lab.index for lab in out}
        for k, s in enumerate(trace):
            if k not in labelled and s.learner_action is not None:
                out.append(Label(k, s.learner_action, self_labelled=True))
        return sorted(out, key=lambda lab: lab.index)

    def describe(self):
        return {"name": self.name, "base": self.base.describe()}


class CostToGo(Aggregation):
    name = "cost-to-go"

    def __init__(self, scale: float = 10.0, w_max: float = 4.0):
        self.scale, self.w_max = float(scale), float(w_max)

    def select(self, trace, ctx):
        ts = ctx.switch_time
        if ts is None:  # first episode: all expert
            return ExpertLabels("acting").select(trace, ctx)
        start = next((k for k, s in enumerate(trace) if s.t == ts), None)
        if start is None:
            return []
        q = 0.0
        for s in trace[start:]:
            if s.out_of_bounds:
                q -= self.scale * self.w_max  # the failure is the worst cost; -1000 stays excluded
                break
            q += s.reward
        ctx.cost_to_go = q
        w = 1.0 + min(self.w_max, max(0.0, -q) / self.scale)
        out = []
        for k in range(start, len(trace)):
            s = trace[k]
            if s.expert_action is not None and (k == start or s.actor == EXPERT):
                out.append(Label(k, s.expert_action, w if k == start else 1.0))
        return out
