"""Inference engine: a bundle's ONNX graph on one frame -> a typed :class:`Prediction`.

onnxruntime only (no torch). :meth:`Engine.predict` never raises for a bad frame or a failing
session: it returns ``Prediction(ok=False, error=...)`` so the audio path never sees an
exception. Opening an engine does raise (:class:`~crossing_assist.bundle.BundleError`) for a
bundle that cannot be used, with one line saying why.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from crossing_assist import inference
from crossing_assist.bundle import UNCERTAINTY_MEASURES, Bundle, BundleError
from crossing_assist.geometry import (MAX_GUIDED_ROLL_DEG, ORIENTATIONS, GeometryError, check_fov, check_frame_shape, level,
                                      orientation, rolled_too_far)
from crossing_assist.runtime import belief as bf
from crossing_assist.runtime.decide import DecisionConfig, Observation


@dataclass(frozen=True)
class Prediction:
    """Model outputs for one frame.

    ``probs`` (A,) mean class probabilities; ``entropy`` (nats) and ``mutual_info`` (nats, >= 0);
    ``variance`` (A,) and ``votes`` (A,); ``conformal_set`` the actions with ``probs >=`` the
    bundle's conformal threshold; ``action`` the argmax (0 = unknown); ``heading_deg`` its
    heading (None for unknown) with ``fov_deg``, the camera FOV of the frame's ``orientation``
    (``landscape`` / ``portrait``); ``uncertainty`` the gate's measure; ``latency_s`` inference time.
    ``ok=False`` (with ``error``) when inference failed; the arrays are then None, and
    ``fov_deg`` / ``orientation`` are the frame's when they were known before it failed.
    """

    ok: bool
    probs: np.ndarray | None = None
    entropy: float = math.inf
    mutual_info: float = math.inf
    variance: np.ndarray | None = None
    votes: np.ndarray | None = None
    conformal_set: tuple[int, ...] = ()
    action: int = 0
    heading_deg: float | None = None
    fov_deg: float | None = None
    orientation: str | None = None
    uncertainty: float = math.inf
    latency_s: float = 0.0
    error: str = ""
    extra: dict = field(default_factory=dict, repr=False)

    def observation(self) -> Observation:
        """What the decision logic needs from this prediction."""
        return Observation(probs=self.probs, uncertainty=self.uncertainty, ok=self.ok)


def measure_value(measure: str, entropy: float, mutual_info: float, variance: np.ndarray, probs: np.ndarray) -> float:
    """The gate's frame uncertainty: ``entropy``, ``mutual_info``, ``variance[argmax probs]`` or
    ``far_mass`` (:func:`~crossing_assist.runtime.belief.far_mass` of ``probs``)."""
    if measure == "entropy":
        return float(entropy)
    if measure == "mutual_info":
        return float(mutual_info)
    if measure == "variance":
        return float(variance[int(np.argmax(probs))])
    if measure == "far_mass":
        return bf.far_mass(probs)
    raise ValueError(f"Unknown uncertainty measure: {measure!r}; valid: {', '.join(UNCERTAINTY_MEASURES)}")


class Engine:
    """Runs a bundle. ``threads`` = onnxruntime intra-op threads (0 = its default); ``fov_deg``:
    the camera's horizontal field of view (the user's or device's setting; None = the bundle's
    default for each frame's orientation); ``seed``: onnxruntime's random seed for the MC-dropout
    masks (:func:`~crossing_assist.inference.open_session`), so a rerun on the same frames makes the
    same decisions (None: the per-process seed). A FOV outside 20..170 degrees or a bad seed raises
    BundleError."""

    def __init__(self, bundle_dir: str | Path, *, threads: int = 1, fov_deg: float | None = None,
                 seed: int | None = 0) -> None:
        try:
            self.fov_override = None if fov_deg is None else check_fov(fov_deg)
        except GeometryError as exc:
            raise BundleError(str(exc)) from None
        if seed is not None and not inference.is_seed(seed):
            raise BundleError(f"Invalid seed {seed!r}; valid: {inference.SEED_RANGE}")
        self.bundle: Bundle
        self.bundle, self.session = inference.open_session(bundle_dir, threads=threads, inter_threads=1 if threads else 0,
                                                           quiet=True, seed=seed)
        self.space = self.bundle.space
        self.measure = self.bundle.calibration.uncertainty.measure
        self.conformal_threshold = self.bundle.calibration.conformal.threshold
        self._clock: Callable[[], float] = time.perf_counter

    def camera_fov(self, width: int, height: int, fov_deg: float | None = None) -> float:
        """Horizontal FOV (degrees) for a ``width x height`` frame: ``fov_deg`` (this frame's),
        else the engine's override, else the bundle's default for the frame's orientation."""
        return self.bundle.camera_fov(width, height, self.fov_override if fov_deg is None else fov_deg)

    def decision_config(self, orientation: str = "landscape", fov_deg: float | None = None,
                        **overrides) -> DecisionConfig:
        """The decision logic's config for this bundle and frames of ``orientation`` from a camera
        ``fov_deg`` across (None: the override, else the bundle's for a full-sensor frame):
        actions, measure, FOV and the gate threshold for that orientation and FOV
        (:meth:`~crossing_assist.bundle.UncertaintySpec.threshold_for`). A starting point:
        :class:`Pipeline` and ``listen.decide_still`` take each frame's own FOV
        (:meth:`camera_fov`: a crop narrower than the sensor, e.g. 9:16 video with
        ``geometry.sensor_aspect``, gets a narrower one) and orientation."""
        unc = self.bundle.calibration.uncertainty
        fov = fov_deg or self.fov_override or self.bundle.geometry.camera_fov_deg[ORIENTATIONS.index(orientation)]
        kw = {"fov_deg": fov, "measure": unc.measure, "threshold": unc.threshold_for(orientation, fov), **overrides}
        return DecisionConfig(n_actions=self.bundle.actions.n, **kw)

    def frame_fov(self, frame_rgb: np.ndarray) -> float | None:
        """The FOV :meth:`predict` gives this frame (None where it refuses the frame before knowing
        it), without running the model: a turn can be read from the frame first."""
        try:
            self._check_frame(frame_rgb)
            return self.camera_fov(frame_rgb.shape[1], frame_rgb.shape[0])
        except Exception:  # noqa: BLE001  predict says why
            return None

    def _check_frame(self, frame: np.ndarray) -> np.ndarray:
        frame = inference.check_frame(frame)
        check_frame_shape(frame.shape[0], frame.shape[1])   # e.g. 1 x N or 1:10: never a heading
        return frame

    def predict(self, frame_rgb: np.ndarray, fov_deg: float | None = None, roll_deg: float | None = None) -> Prediction:
        """Run one H x W x 3 uint8 RGB frame (turned level first when ``roll_deg`` says how far the
        camera is rolled, :func:`~crossing_assist.geometry.level`, e.g. from a board's or phone's
        orientation sensor; then its rows cropped to the training camera's view when the bundle
        says so, :meth:`Bundle.view`); failures come back as ``Prediction(ok=False)``.
        ``fov_deg``: this frame's camera FOV (:meth:`camera_fov`)."""
        t0 = self._clock()
        fov = orient = None   # a frame that fails after its FOV is known still says it (Pipeline)
        try:
            x = self._check_frame(frame_rgb)
            fov = self.camera_fov(frame_rgb.shape[1], frame_rgb.shape[0], fov_deg)
            orient = orientation(frame_rgb.shape[1], frame_rgb.shape[0])
            if rolled_too_far(roll_deg):
                raise ValueError(f"the camera is rolled {roll_deg:+.0f} deg, more than {MAX_GUIDED_ROLL_DEG:g} "
                                 "can be levelled: hold the phone level")
            if roll_deg is not None:
                x = level(x, roll_deg, self.bundle.geometry.pad_rgb)
            outs = inference.run(self.session, self.bundle.view(x, fov)[None])
            probs, ent, mi, var, votes = (np.asarray(outs[k], dtype=np.float64)[0] for k in
                                          ("probs", "entropy", "mutual_info", "variance", "votes"))
            if probs.shape != (self.space.n,) or not np.all(np.isfinite(probs)):
                raise ValueError(f"model returned probs of shape {probs.shape} with non-finite values"
                                 if probs.shape == (self.space.n,) else
                                 f"model returned probs of shape {probs.shape}; expected ({self.space.n},)")
            action = int(np.argmax(probs))
            unc = measure_value(self.measure, float(ent), float(mi), var, probs)
            if not math.isfinite(unc):
                raise ValueError(f"model returned a non-finite {self.measure}")
            return Prediction(
                ok=True, probs=probs, entropy=float(ent), mutual_info=float(mi), variance=var, votes=votes,
                conformal_set=tuple(int(a) for a in np.flatnonzero(probs >= self.conformal_threshold)),
                action=action,
                heading_deg=None if action == 0 else self.space.action_heading(action, fov), fov_deg=fov,
                orientation=orient, uncertainty=unc, latency_s=self._clock() - t0,
            )
        except Exception as exc:  # never raise into the audio path
            return Prediction(ok=False, error=f"{type(exc).__name__}: {str(exc).splitlines()[0][:300] if str(exc) else ''}",
                              fov_deg=fov, orientation=orient, latency_s=self._clock() - t0)
