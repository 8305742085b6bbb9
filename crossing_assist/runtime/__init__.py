"""Torch-free runtime: engine, temporal filter, UPMS gate, beacon, audio out, demo.

numpy + onnxruntime + opencv (+ soundfile); sounddevice is imported only when a live stream
opens. Never imports torch or the ``models``/``export``/``iil`` subpackages. See
docs/runtime.md for the decision logic's full specification.
"""

from crossing_assist.runtime.audio import AudioDeviceError, LiveAudio, write_wav
from crossing_assist.runtime.beacon import BeaconConfig, Cue, CuePlayer, cue_for, render_cue
from crossing_assist.runtime.decide import Decider, Decision, DecisionConfig, Observation
from crossing_assist.runtime.engine import Engine, Prediction
from crossing_assist.runtime.pipeline import Pipeline, Step

__all__ = [
    "AudioDeviceError", "BeaconConfig", "Cue", "CuePlayer", "Decider", "Decision", "DecisionConfig", "Engine",
    "LiveAudio", "Observation", "Pipeline", "Prediction", "Step", "cue_for", "render_cue", "write_wav",
]
