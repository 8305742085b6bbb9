"""Interactive imitation learning: experts, mixing/sampling/aggregation strategies, the one
loop (the thesis's Algorithm 4.1), learners, environments, runs and reports.

Uses torch and gymnasium (imported by the submodules that need them, so ``crossing-iil
report`` stays light); the torch-free runtime never imports this package.
Entry points: :func:`crossing_assist.iil.algorithms.create`, :func:`crossing_assist.iil.runner.run`,
:func:`crossing_assist.iil.report.write_report`, the ``crossing-iil`` command.
"""
