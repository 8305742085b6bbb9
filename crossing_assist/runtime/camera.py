"""A frame's field of view and gate threshold from a bundle.json's own blocks (pure Python).

The camera-geometry contract (docs/contracts.md, "Camera geometry") on the JSON the phone app
reads: :func:`geometry_of` (schema 1 reads as one FOV for both orientations),
:func:`camera_fov` (the frame's orientation -> the override or the bundle's ``camera_fov_deg``,
narrowed to a crop's with ``sensor_aspect``, refused outside 20..170 degrees) and :func:`gate_threshold` (the orientation's threshold, a narrow camera's in portrait; by the camera's width with ``wide_fov_deg``).
They agree with :meth:`crossing_assist.bundle.Bundle.camera_fov` and
:meth:`~crossing_assist.bundle.UncertaintySpec.threshold_for`, which they call; the app's
``android_demo/www/js/geometry.js`` is the same rule, checked against the shared test vectors
(``python -m crossing_assist.testing.vectors``).
"""

from __future__ import annotations

from crossing_assist.bundle import UncertaintySpec
from crossing_assist.geometry import Geometry, orientation


def geometry_of(meta: dict) -> dict:
    """A bundle.json's geometry block; schema 1 reads as ``fit=stretch`` with its ``fov_deg``
    for both orientations."""
    if meta.get("schema_version", 1) >= 2:
        return meta["geometry"]
    fov = float(meta["fov_deg"])
    return {"fit": "stretch", "strips": "frame", "camera_fov_deg": {"landscape": fov, "portrait": fov},
            "train_fov_deg": fov}


def camera_fov(geometry: dict, width: int, height: int, override: float | None = None) -> float:
    """Horizontal FOV (degrees) for a ``width x height`` frame: ``override`` (the user's or the
    device's value for this orientation) if given, else ``geometry.camera_fov_deg`` of the
    frame's orientation, or its crop's FOV when ``geometry.sensor_aspect`` says the frame is
    narrower than the sensor (:func:`crossing_assist.geometry.default_fov`). Raises ValueError
    outside 20..170 degrees (the runtime then plays the stop cue)."""
    cam = geometry["camera_fov_deg"]
    return Geometry(camera_fov_deg=(cam["landscape"], cam["portrait"]),
                    sensor_aspect=geometry.get("sensor_aspect")).camera_fov(width, height, override)


def gate_threshold(uncertainty: dict, width: int, height: int, fov_deg: float | None = None) -> float:
    """The gate threshold for a ``width x height`` frame from a camera ``fov_deg`` across (its
    :func:`camera_fov`), by :meth:`UncertaintySpec.which` from a bundle's ``calibration.uncertainty``:
    ``narrow_threshold`` for portrait frames at most ``narrow_fov_deg`` across when it has one, else
    ``portrait_threshold`` for portrait frames when it has one, else its ``threshold``; with
    ``wide_fov_deg``, by the camera's width whatever the orientation (narrower than it: portrait)."""
    spec = UncertaintySpec(uncertainty.get("measure", "entropy"), uncertainty["threshold"],
                           uncertainty.get("portrait_threshold"), narrow_threshold=uncertainty.get("narrow_threshold"),
                           narrow_fov_deg=uncertainty.get("narrow_fov_deg"), wide_fov_deg=uncertainty.get("wide_fov_deg"))
    return spec.threshold_for(orientation(width, height), fov_deg)
