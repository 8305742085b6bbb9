"""Monte-Carlo dropout, the one copy: the explicit-mask dropout layer and the summaries of T
samples (mean probabilities, entropy, mutual information, variance, votes). torch only.

Used by the policy heads (:mod:`crossing_assist.models.heads`), the bundle's ONNX graph
(:mod:`crossing_assist.export.graph`) and the IIL learners (:mod:`crossing_assist.iil.networks`,
:mod:`crossing_assist.iil.learners`). The masks are explicit (``rand_like(x) >= p``, exported to
ONNX as ``RandomUniformLike``) because ``nn.Dropout`` and ``Dropout`` nodes are removed by export
in eval mode and by onnxruntime's graph optimiser (docs/contracts.md, section 3).
"""

from __future__ import annotations

import torch


def mc_dropout(x: torch.Tensor, p: float, active: bool, generator: torch.Generator | None = None) -> torch.Tensor:
    """Explicit-mask dropout: ``x * (u >= p) * (1 / (1 - p))`` with ``u ~ U[0, 1)`` of ``x``'s
    shape when ``active`` and ``p > 0``; else ``x`` itself. ``generator`` given: ``u`` is drawn
    from it (reproducible streams, e.g. the IIL's); None: ``rand_like`` (what ONNX export needs)."""
    if not active or p <= 0.0:
        return x
    if generator is None:
        u = torch.rand_like(x)
    else:
        u = torch.rand(x.shape, generator=generator, dtype=x.dtype, device=x.device)
    return x * (u >= p).to(x.dtype) * (1.0 / (1.0 - p))


def mc_summaries(logits: torch.Tensor, temperature: float = 1.0) -> tuple[torch.Tensor, ...]:
    """Summaries of T samples of logits ``[T, N, A]`` (any float dtype; computed in it).

    Returns ``probs`` [N, A] (mean softmax of ``logits / temperature``), ``entropy`` [N] (nats,
    of ``probs``: the predictive entropy), ``mutual_info`` [N] (``entropy`` minus the mean
    per-sample entropy, clipped at 0: the samples' disagreement), ``variance`` [N, A] (population
    variance of the per-sample probabilities) and ``votes`` [N, A] (fraction of samples whose
    argmax is each action). ``0 log 0`` counts as 0.
    """
    logp = torch.log_softmax(logits / temperature, dim=-1)
    p_s = logp.exp()
    probs = p_s.mean(0)
    entropy = -(probs * torch.log(probs.clamp_min(1e-30))).sum(-1)
    expected = -(p_s * logp).sum(-1).mean(0)
    mutual_info = (entropy - expected).clamp_min(0.0)
    variance = (p_s - probs.unsqueeze(0)).square().mean(0)
    n_actions = logits.shape[-1]
    top = p_s.argmax(-1, keepdim=True)  # [T, N, 1]
    arange = torch.arange(n_actions, device=logits.device).view(1, 1, n_actions)
    votes = (top == arange).to(probs.dtype).mean(0)
    return probs, entropy, mutual_info, variance, votes
