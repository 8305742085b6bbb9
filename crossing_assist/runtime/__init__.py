"""Torch-free runtime: engine, temporal filter, UPMS gate, beacon, audio out, demo.

numpy + onnxruntime + opencv (+ soundfile); sounddevice is imported only inside the live-audio
functions. Never imports torch or the ``models``/``export``/``iil`` subpackages.
"""
