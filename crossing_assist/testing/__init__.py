"""Generators of test data shared with other implementations (not part of the runtime).

* :mod:`.vectors` — the decision test vectors the phone app replays
  (``python -m crossing_assist.testing.vectors --out android_demo/test_vectors.json``).
"""
