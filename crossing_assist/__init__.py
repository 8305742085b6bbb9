"""crossing_assist: street-crossing guidance for blind pedestrians.

Data path: ``data_tools`` (frames, labels, datasets) -> ``models`` (train, evaluate)
-> ``export`` (ONNX bundle) -> ``runtime`` (torch-free engine, gate, beacon, demo);
``iil`` (interactive imitation learning) sits beside. ``actions`` and ``bundle`` are
shared by all and import neither torch nor each other's heavy dependencies.
"""

__version__ = "0.1.0"
