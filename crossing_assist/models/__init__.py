"""Policy models: backbones, heads with export-safe MC dropout, training and evaluation.

Submodules (import them directly; this package imports nothing, so that the numpy-only
:mod:`crossing_assist.models.metrics` can be used without torch):

* :mod:`.backbones` — ``create_backbone`` / ``list_backbones`` / ``Backbone`` / ``BackboneFacts``
* :mod:`.heads` — ``create_head`` (``spatial``, ``spatial_mlp``, ``thesis``, ``thesis_fc``)
* :mod:`.policy` — ``Policy``, ``PolicyConfig``; :mod:`.checkpoint` — ``save_checkpoint`` / ``load_policy``
* :mod:`.metrics` — ``compute_metrics`` (numpy only); :mod:`.plots` — training and evaluation figures
* :mod:`.train` / :mod:`.evaluate` / :mod:`.cli` — ``crossing-train`` and ``crossing-eval``
"""
