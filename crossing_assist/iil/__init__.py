"""Interactive imitation learning: experts, mixing/sampling/aggregation strategies, the one
loop (the thesis's Algorithm 4.1), learners, environments, runs and reports.

Uses torch and gymnasium; the torch-free runtime never imports this package.
"""

from .algorithms import THESIS_ALGORITHMS, AlgoParams, create, list_algorithms
from .mixing import EXPERT, EXPLORER, LEARNER, coefficient, rational_mixing

__all__ = ["THESIS_ALGORITHMS", "AlgoParams", "create", "list_algorithms", "EXPERT", "EXPLORER", "LEARNER",
           "coefficient", "rational_mixing"]
