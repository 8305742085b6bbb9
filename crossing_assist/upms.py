"""UPMS's preferential coefficient ``alpha(U) = 1 - tanh(c U)``: the one copy, pure Python.

Used by the torch-free runtime's gate (:mod:`crossing_assist.runtime.gate`) and by the IIL
mixing and sampling laws (:mod:`crossing_assist.iil.mixing`), so that both trust an uncertainty
the same way. ``c = SATURATION_HALF / threshold`` puts ``alpha(threshold) = 1/2``; the thesis's
configuration uses ``c = 30`` instead.

Contract of :func:`coefficient` (``U`` in the agent's own units, ``c > 0``):

* ``0 <= U < inf``: ``alpha`` in ``(0, 1]``, ``alpha(0) = 1``, decreasing in ``U``; computed as
  ``2 / (1 + exp(2 c U))``, the same number as ``1 - tanh(c U)`` without the cancellation that
  makes the latter exactly 0 for ``c U > 19`` (with ``c = 30`` every ``U > 0.63`` would tie at 0
  and the rational law would call it impossible). Below ``1e-300`` (``2 c U > 700``) it is 0.
* ``U = +inf`` (no answer), ``-inf`` or NaN (no valid measurement): exactly 0. A policy without
  a valid uncertainty is never trusted, and the real-time gate never raises on a bad number.
* finite ``U < 0`` (rounding noise of a measure that is >= 0 in exact arithmetic, such as an
  entropy): read as 0, so ``alpha = 1``.
"""

from __future__ import annotations

import math

SATURATION_HALF = math.atanh(0.5)  # c * threshold for which alpha(threshold) == 1/2
_MAX_EXP = 700.0  # exp(700) ~ 1e304: beyond it the coefficient is below 1e-300


def coefficient(uncertainty: float, c: float) -> float:
    """``alpha(U) = 1 - tanh(c U)`` in [0, 1] (module docstring: NaN and +-inf give 0, finite
    negatives count as 0)."""
    u = float(uncertainty)
    if not math.isfinite(u):
        return 0.0
    x = 2.0 * c * max(u, 0.0)
    if x > _MAX_EXP:
        return 0.0
    return 2.0 / (1.0 + math.exp(x))


def saturation(threshold: float) -> float:
    """The ``c`` for which ``coefficient(threshold, c) == 1/2``; ``threshold`` > 0 (units of U)."""
    if not float(threshold) > 0:
        raise ValueError(f"Invalid uncertainty threshold: {threshold}; valid: > 0")
    return SATURATION_HALF / float(threshold)
