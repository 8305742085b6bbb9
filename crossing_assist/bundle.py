"""The deployment bundle: ``model.onnx`` + ``bundle.json`` in one folder (numpy + json only).

A bundle is what the runtime, a phone or a board runs. :func:`read_bundle` validates every
field of ``bundle.json`` and the model file's size and SHA-256, and raises :class:`BundleError`
with one line naming the field and the fix. :func:`write_bundle` writes a whole bundle
atomically (into a temporary sibling folder, validated, then renamed into place), so a crash
never leaves half a bundle. :func:`check_session` compares an opened onnxruntime session (passed
in, never imported here) with the json: input name and dtype, output names, action count and
the facts embedded in the graph's metadata.

Schema (version 4; versions 1 to 3 are still read), see docs/contracts.md section 3. Version 2
adds ``geometry`` (:class:`crossing_assist.geometry.Geometry`: how the graph fits a frame onto its
canvas, and the default camera field of view per orientation); a version-1 bundle reads as
``fit = stretch`` with ``fov_deg`` for both orientations. Version 3 adds ``geometry.view_crop``
(letterbox bundles, absent = false; the consumer crops the frame's rows to the training camera's view before
the graph, :func:`crossing_assist.geometry.view_rows`); a version-2 bundle reads as no crop.
``geometry.sensor_aspect`` (optional, schema 2 and 3, 1..3; absent or null = none) is the long /
short side of the sensor ``camera_fov_deg`` describes: the default FOV of a frame narrower than
it is its crop's (:func:`crossing_assist.geometry.default_fov`); older readers ignore it.
Version 4 adds ``geometry.view_zoom`` (with the view crop, 1..4, absent = 1): a frame from a camera
narrower than the training one is shown magnified by up to this much instead of at the training
scale. A bundle is written as version 4 only when its ``view_zoom`` is not 1 (:func:`schema_for`),
so bundles without it stay readable by version-3 readers. Readers that predate a version refuse
it, so no consumer silently skips the crop or the zoom. Two fields depend on the model bytes and
are filled in by :func:`write_bundle`: ``model_sha256`` and ``model_size`` (bytes). They are the
only fields left out of the copy embedded in the ONNX metadata (``bundle_json``).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from crossing_assist import __version__
from crossing_assist.actions import DEFAULT_FOV_DEG, VALID_SPACES, ActionSpace, get_space
from crossing_assist.errors import UserError
from crossing_assist.errors import short_repr as _short  # one cut-to-length repr for every error line
from crossing_assist.geometry import (FITS, FOV_RANGE_DEG, PAD_RGB, SENSOR_ASPECT_RANGE, VIEW_ZOOM_RANGE, Geometry, GeometryError,
                                     check_fov)

SCHEMA_VERSION = 4
READABLE_SCHEMAS = (1, 2, 3, 4)
BUNDLE_JSON = "bundle.json"
MODEL_FILE = "model.onnx"
INPUT_NAME = "frames"
OUTPUT_NAMES = ("probs", "entropy", "mutual_info", "variance", "votes")
UNCERTAINTY_MEASURES = ("entropy", "mutual_info", "variance", "far_mass")
PRECISIONS = ("fp32", "int8")
BYTE_FIELDS = ("model_sha256", "model_size")
MIN_ONNX_BYTES = 64
MAX_ONNX_BYTES = 1 << 40  # 1 TiB: any larger model_size is a corrupt bundle.json
MAX_NAME = 200          # longest model_file accepted (file systems stop at 255 bytes)
MAX_JSON_BYTES = 1 << 22  # a bundle.json is a few kB; refuse anything absurd before parsing it
#: The bundle.json keys check_session compares with the graph's embedded copy (the app: bundle.js EMBEDDED_KEYS).
EMBEDDED_KEYS = ("schema_version", "actions", "fov_deg", "input", "geometry", "mc", "calibration", "precision")


class BundleError(UserError):
    """A bundle that cannot be used; the message is one line naming the problem and the fix."""


@dataclass(frozen=True)
class ActionsSpec:
    """The action space: ``n`` in 4/8/13, ``names[a]``, ``bins[a]`` (bins 1..12; ``()`` = unknown)."""

    n: int
    names: tuple[str, ...]
    bins: tuple[tuple[int, ...], ...]

    @property
    def space(self) -> ActionSpace:
        return get_space(self.n)

    @classmethod
    def of(cls, n: int) -> "ActionsSpec":
        """The spec of the ``n``-action space (names and bins from :mod:`crossing_assist.actions`)."""
        if isinstance(n, bool) or n not in VALID_SPACES:
            raise BundleError(f"bundle: actions.n = {_short(n)} invalid; valid: 4, 8, 13")
        space = get_space(n)
        return cls(n=space.n, names=tuple(space.names), bins=tuple(tuple(g) for g in space.groups))

    def to_json(self) -> dict:
        return {"n": self.n, "names": list(self.names), "bins": [list(g) for g in self.bins]}


@dataclass(frozen=True)
class InputSpec:
    """Input of the graph: uint8 NHWC RGB frames, resized to ``size`` = (H, W) and normalised
    with ``(x / 255 - mean) / std`` inside the graph; ``resize`` describes the resize (free text,
    optional)."""

    size: tuple[int, int]
    mean: tuple[float, float, float]
    std: tuple[float, float, float]
    layout: str = "NHWC"
    dtype: str = "uint8"
    color: str = "RGB"
    resize: str = ""

    def to_json(self) -> dict:
        d = {"layout": self.layout, "dtype": self.dtype, "color": self.color, "size": list(self.size),
             "mean": list(self.mean), "std": list(self.std)}
        if self.resize:
            d["resize"] = self.resize
        return d


@dataclass(frozen=True)
class McSpec:
    """MC dropout: ``samples`` (T) head samples per frame with drop probability ``p``;
    ``mirror``: the graph also runs the frame mirrored left-right (actions mapped back) and
    summarises the 2T samples of both (mirror test-time augmentation, twice the backbone's cost).
    Absent in bundle.json = False (bundles from before it). ``members`` > 1: the graph is an
    ensemble of that many models trained alike, each with these settings, their samples pooled
    (:mod:`crossing_assist.export.ensemble`; the members' summed cost a frame). Absent = 1; the
    graph's inputs and outputs are a single model's, so readers that predate it run it unchanged."""

    samples: int
    p: float
    mirror: bool = False
    members: int = 1

    def to_json(self) -> dict:
        return {"samples": self.samples, "p": self.p, **({"mirror": True} if self.mirror else {}),
                **({"members": self.members} if self.members > 1 else {})}


@dataclass(frozen=True)
class ConformalSpec:
    """Split-conformal sets ``{a : probs[a] >= threshold}`` cover the true action with
    probability ``coverage`` (fitted on ``n_frames`` held-back frames; 0 = not calibrated, and
    then ``threshold`` is 0: every action is in the set)."""

    coverage: float
    threshold: float
    n_frames: int

    def to_json(self) -> dict:
        return {"coverage": self.coverage, "threshold": self.threshold, "n_frames": self.n_frames}


@dataclass(frozen=True)
class UncertaintySpec:
    """The gate's learner uncertainty: output ``measure``; ``threshold`` is its value where the
    gate's coefficient should be about one half, for landscape frames; ``portrait_threshold``
    the same for portrait frames (optional; absent = ``threshold``). A portrait strip is narrower
    (0.56 of a landscape one with a 3:4 frame on a 4:3 canvas), so the same doubt in degrees
    spreads over more strips and reads as a higher entropy. ``narrow_threshold`` (optional, with
    ``narrow_fov_deg``): the threshold for portrait frames whose camera sees at most
    ``narrow_fov_deg`` across (e.g. 9:16 portrait video, ~41 deg), whose central goals spread over
    neighbouring strips; older readers ignore it and give such frames the stricter
    ``portrait_threshold``. ``wide_fov_deg`` (optional): the camera's width picks the threshold,
    whatever the frame's orientation: frames at least ``wide_fov_deg`` across take ``threshold``
    (chosen on landscape photos), narrower ones ``portrait_threshold`` (chosen on a phone held in
    portrait; a square frame of the same sensor sees what that phone sees) and those at most
    ``narrow_fov_deg`` across ``narrow_threshold``; older readers ignore it and go by orientation.
    ``fitted_threshold`` (optional, informative): the threshold as fitted
    on the calibration frames, before the held-out scales (``scripts/choose_gate.py``) made
    ``threshold`` and ``portrait_threshold``; tools that re-scale the gate start from it
    (``scripts/stamp_bundle.py --rescale-gate``)."""

    measure: str
    threshold: float
    portrait_threshold: float | None = None
    fitted_threshold: float | None = None
    narrow_threshold: float | None = None
    narrow_fov_deg: float | None = None
    wide_fov_deg: float | None = None

    def __post_init__(self) -> None:
        if (self.narrow_threshold is None) != (self.narrow_fov_deg is None):
            raise ValueError("narrow_threshold and narrow_fov_deg go together; set both or neither")
        if None not in (self.wide_fov_deg, self.narrow_fov_deg) and self.wide_fov_deg <= self.narrow_fov_deg:
            raise ValueError(f"wide_fov_deg {self.wide_fov_deg:g} must exceed narrow_fov_deg {self.narrow_fov_deg:g}")

    def which(self, orientation: str, fov_deg: float | None = None) -> str:
        """Which threshold frames of this orientation (``landscape`` or ``portrait``) from a
        camera ``fov_deg`` across (None: the orientation's own) take: ``landscape`` (the
        ``threshold``), ``portrait`` or ``narrow``; with ``wide_fov_deg`` and a known FOV, by the
        camera's width alone."""
        narrow = self.narrow_threshold is not None and fov_deg is not None and fov_deg <= self.narrow_fov_deg
        if self.wide_fov_deg is not None and fov_deg is not None:
            portrait = fov_deg < self.wide_fov_deg
        elif orientation != "portrait":
            return "landscape"
        else:
            portrait = True
        return "narrow" if narrow else "portrait" if portrait and self.portrait_threshold is not None else "landscape"

    def threshold_for(self, orientation: str, fov_deg: float | None = None) -> float:
        """The threshold for frames of this orientation from a camera ``fov_deg`` across (:meth:`which`)."""
        return {"landscape": self.threshold, "portrait": self.portrait_threshold,
                "narrow": self.narrow_threshold}[self.which(orientation, fov_deg)]

    def describe(self, orientation: str, fov_deg: float | None = None) -> str:
        """The gate threshold a frame gets, in words: ``far_mass 0.0383 (a narrow camera's:
        portrait frames at most 42 deg across)``."""
        which = self.which(orientation, fov_deg)
        if which == "narrow":
            frames = "portrait frames" if self.wide_fov_deg is None else "frames"
            why = f"a narrow camera's: {frames} at most {self.narrow_fov_deg:g} deg across"
        elif self.wide_fov_deg is not None and fov_deg is not None:
            why = f"{which}: frames {'under' if which == 'portrait' else 'at least'} {self.wide_fov_deg:g} deg across"
        else:
            why = which
        return f"{self.measure} {self.threshold_for(orientation, fov_deg):.4g} ({why})"

    def to_json(self) -> dict:
        d = {"measure": self.measure, "threshold": self.threshold}
        for k in ("portrait_threshold", "narrow_threshold", "narrow_fov_deg", "wide_fov_deg", "fitted_threshold"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        return d


@dataclass(frozen=True)
class Calibration:
    """Temperature (divides the logits inside the graph), conformal set, gate threshold."""

    temperature: float
    conformal: ConformalSpec
    uncertainty: UncertaintySpec

    def to_json(self) -> dict:
        return {"temperature": self.temperature, "conformal": self.conformal.to_json(),
                "uncertainty": self.uncertainty.to_json()}


@dataclass(frozen=True)
class Bundle:
    """A validated bundle. ``dir`` is its folder; ``model_path`` its ONNX file."""

    dir: Path
    schema_version: int
    model_file: str
    actions: ActionsSpec
    fov_deg: float
    input: InputSpec
    mc: McSpec
    calibration: Calibration
    precision: str
    training: Mapping[str, Any]
    metrics: Mapping[str, Any]
    package_version: str
    provenance: Mapping[str, Any]
    model_sha256: str
    model_size: int
    geometry: Geometry = field(default_factory=Geometry)
    raw: Mapping[str, Any] = field(repr=False, compare=False, default_factory=dict)

    def camera_fov(self, width: int, height: int, override: float | None = None) -> float:
        """Horizontal FOV (degrees) that turns strips of a ``width x height`` frame into
        headings: ``override`` (the user's or device's) if given, else this bundle's default for
        the frame's orientation and aspect (:meth:`Geometry.camera_fov`). Raises GeometryError
        outside 20..170 degrees."""
        return self.geometry.camera_fov(width, height, override)

    def view(self, frame, fov_deg: float):
        """What of an H x W x 3 frame (horizontal FOV ``fov_deg``) goes into the graph: its rows
        cropped to the training camera's view when ``geometry.view_crop`` (schema 3), else all."""
        return self.geometry.view(frame, fov_deg, self.input.size)

    def rows_seen(self, height: int, width: int, fov_deg: float) -> tuple[int, int]:
        """``(top, rows)`` of a ``height x width`` frame that :meth:`view` keeps."""
        return self.geometry.rows_seen(height, width, fov_deg, self.input.size)

    @property
    def model_path(self) -> Path:
        return self.dir / self.model_file

    @property
    def space(self) -> ActionSpace:
        return self.actions.space


# ----------------------------------------------------------------------------- validation helpers


def _get(d: Mapping[str, Any], key: str, where: str) -> Any:
    if not isinstance(d, Mapping):
        raise BundleError(f"bundle.json: {where} must be an object; rewrite it with crossing-export")
    if key not in d:
        raise BundleError(f"bundle.json: missing field '{where}.{key}'".replace("'.", "'")
                          + "; re-export the bundle with crossing-export")
    return d[key]


def _num(value: Any, name: str, lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise BundleError(f"bundle.json: {name} = {_short(value)} is not a finite number")
    try:
        finite = math.isfinite(value)
    except OverflowError:  # an integer beyond float range
        finite = False
    if not finite:
        raise BundleError(f"bundle.json: {name} = {_short(value)} is not a finite number")
    ok_lo = value > lo if lo_open else value >= lo
    ok_hi = value < hi if hi_open else value <= hi
    if not (ok_lo and ok_hi):
        rng = f"{'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
        raise BundleError(f"bundle.json: {name} = {_short(value)} is out of range; valid: {rng}")
    return float(value)


def _int(value: Any, name: str, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise BundleError(f"bundle.json: {name} = {_short(value)} must be an integer")
    if value < lo or (hi is not None and value > hi):
        valid = f"{lo}..{hi}" if hi is not None else f">= {lo}"
        raise BundleError(f"bundle.json: {name} = {_short(value)} is out of range; valid: {valid}")
    return value


def _bool(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise BundleError(f"bundle.json: {name} = {_short(value)} must be true or false")
    return value


def _choice(value: Any, name: str, valid: tuple) -> Any:
    if value not in valid:
        raise BundleError(f"bundle.json: {name} = {_short(value)} unknown; valid: {', '.join(map(str, valid))}")
    return value


def _triple(value: Any, name: str, *, positive: bool) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise BundleError(f"bundle.json: {name} must be a list of 3 numbers (R, G, B), got {_short(value)}")
    lo = 0.0
    return tuple(_num(v, f"{name}[{i}]", lo, 1e6, lo_open=positive) for i, v in enumerate(value))  # type: ignore


def _parse_actions(d: Any) -> ActionsSpec:
    n = _get(d, "n", "actions")
    if isinstance(n, bool) or not isinstance(n, int) or n not in VALID_SPACES:
        raise BundleError(f"bundle.json: actions.n = {_short(n)} invalid; valid: 4, 8, 13")
    spec = ActionsSpec.of(n)
    want = spec.to_json()
    names, bins = _get(d, "names", "actions"), _get(d, "bins", "actions")
    if names != want["names"]:
        raise BundleError(f"bundle.json: actions.names {_short(names)} disagree with the {n}-action space "
                          f"{want['names']!r}; re-export the bundle")
    if bins != want["bins"]:
        raise BundleError(f"bundle.json: actions.bins disagree with the {n}-action space "
                          f"{want['bins']!r}; re-export the bundle")
    return spec


def _parse_input(d: Any) -> InputSpec:
    for key, want in (("layout", "NHWC"), ("dtype", "uint8"), ("color", "RGB")):
        got = _get(d, key, "input")
        if got != want:
            raise BundleError(f"bundle.json: input.{key} = {_short(got)} unsupported; valid: {want!r}")
    size = _get(d, "size", "input")
    if (not isinstance(size, list) or len(size) != 2
            or not all(isinstance(s, int) and not isinstance(s, bool) and 16 <= s <= 4096 for s in size)):
        raise BundleError(f"bundle.json: input.size = {_short(size)} invalid; valid: [H, W] integers in 16..4096")
    return InputSpec(size=(size[0], size[1]), mean=_triple(_get(d, "mean", "input"), "input.mean", positive=False),
                     std=_triple(_get(d, "std", "input"), "input.std", positive=True),
                     resize=_str(d.get("resize", ""), "input.resize"))


def _parse_calibration(d: Any) -> Calibration:
    temp = _num(_get(d, "temperature", "calibration"), "calibration.temperature", 0.0, 100.0, lo_open=True)
    c = _get(d, "conformal", "calibration")
    conformal = ConformalSpec(
        coverage=_num(_get(c, "coverage", "calibration.conformal"), "calibration.conformal.coverage",
                      0.0, 1.0, lo_open=True, hi_open=True),
        threshold=_num(_get(c, "threshold", "calibration.conformal"), "calibration.conformal.threshold", 0.0, 1.0),
        n_frames=_int(_get(c, "n_frames", "calibration.conformal"), "calibration.conformal.n_frames", 0),
    )
    u = _get(d, "uncertainty", "calibration")
    try:
        unc = _uncertainty(u)
    except BundleError:
        raise
    except ValueError as exc:   # the fields' own checks passed; how they stand together did not
        raise BundleError(f"bundle.json: calibration.uncertainty: {exc}") from None
    return Calibration(temperature=temp, conformal=conformal, uncertainty=unc)


def _uncertainty(u: Mapping) -> UncertaintySpec:
    """``calibration.uncertainty``, each field checked (:class:`BundleError`), then together (ValueError)."""
    return UncertaintySpec(
        measure=_choice(_get(u, "measure", "calibration.uncertainty"), "calibration.uncertainty.measure",
                        UNCERTAINTY_MEASURES),
        threshold=_num(_get(u, "threshold", "calibration.uncertainty"), "calibration.uncertainty.threshold",
                       0.0, 1e6, lo_open=True),
        portrait_threshold=None if u.get("portrait_threshold") is None else
        _num(u["portrait_threshold"], "calibration.uncertainty.portrait_threshold", 0.0, 1e6, lo_open=True),
        fitted_threshold=None if u.get("fitted_threshold") is None else
        _num(u["fitted_threshold"], "calibration.uncertainty.fitted_threshold", 0.0, 1e6, lo_open=True),
        narrow_threshold=None if u.get("narrow_threshold") is None else
        _num(u["narrow_threshold"], "calibration.uncertainty.narrow_threshold", 0.0, 1e6, lo_open=True),
        narrow_fov_deg=None if u.get("narrow_fov_deg") is None else
        _num(u["narrow_fov_deg"], "calibration.uncertainty.narrow_fov_deg", *FOV_RANGE_DEG),
        wide_fov_deg=None if u.get("wide_fov_deg") is None else
        _num(u["wide_fov_deg"], "calibration.uncertainty.wide_fov_deg", *FOV_RANGE_DEG),
    )


def _parse_geometry(d: Any, fov_deg: float, version: int) -> Geometry:
    """``geometry`` (schema 2, required) or the schema-1 equivalent (stretch, one FOV)."""
    if version < 2:
        return Geometry(fit="stretch", camera_fov_deg=(fov_deg, fov_deg), train_fov_deg=fov_deg)
    d = _obj(d, "geometry")
    fit = _choice(_get(d, "fit", "geometry"), "geometry.fit", FITS)
    strips = d.get("strips", "frame")
    if strips != "frame":
        raise BundleError(f"bundle.json: geometry.strips = {_short(strips)} unsupported; valid: 'frame'")
    cam = _obj(_get(d, "camera_fov_deg", "geometry"), "geometry.camera_fov_deg")
    fovs = []
    for name in ("landscape", "portrait"):
        v = _num(_get(cam, name, "geometry.camera_fov_deg"), f"geometry.camera_fov_deg.{name}", 0.0, 180.0)
        try:
            fovs.append(check_fov(v))
        except GeometryError as exc:
            raise BundleError(f"bundle.json: geometry.camera_fov_deg.{name}: {exc}") from None
    pad = PAD_RGB   # a stretch bundle pads nothing but a levelled frame's corners, as the app does
    if fit == "letterbox":
        pad = _get(d, "pad_rgb", "geometry")
        if (not isinstance(pad, list) or len(pad) != 3
                or not all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255 for v in pad)):
            raise BundleError(f"bundle.json: geometry.pad_rgb = {_short(pad)} must be three integers 0..255")
    train = _num(d.get("train_fov_deg", fovs[0]), "geometry.train_fov_deg", 0.0, 180.0, lo_open=True, hi_open=True)
    crop = fit == "letterbox" and version >= 3 and _bool(d.get("view_crop", False), "geometry.view_crop")
    aspect = d.get("sensor_aspect")
    if aspect is not None:
        aspect = _num(aspect, "geometry.sensor_aspect", *SENSOR_ASPECT_RANGE)
    zoom = 1.0
    if version >= 4 and d.get("view_zoom") is not None:
        zoom = _num(d["view_zoom"], "geometry.view_zoom", *VIEW_ZOOM_RANGE)
        if zoom != 1 and not crop:
            raise BundleError(f"bundle.json: geometry.view_zoom = {_short(d['view_zoom'])} needs geometry.view_crop true")
    return Geometry(fit=fit, pad_rgb=tuple(pad), camera_fov_deg=(fovs[0], fovs[1]), train_fov_deg=train,
                    view_crop=crop, sensor_aspect=aspect, view_zoom=zoom)


def _str(value: Any, name: str) -> str:
    if not isinstance(value, str):
        raise BundleError(f"bundle.json: {name} = {_short(value)} must be a string")
    return value


def _obj(value: Any, name: str) -> Mapping[str, Any]:
    if not isinstance(value, dict):
        raise BundleError(f"bundle.json: {name} must be an object, got {type(value).__name__}")
    return value


def parse_meta(meta: Mapping[str, Any], bundle_dir: Path | str = ".", *, need_bytes: bool = True) -> Bundle:
    """Validate a bundle.json dict; ``need_bytes=False`` accepts it without model_sha256/size
    (the copy embedded in the ONNX metadata). Raises :class:`BundleError`."""
    if not isinstance(meta, Mapping):
        raise BundleError("bundle.json: the top level must be a JSON object; re-export the bundle")
    version = _get(meta, "schema_version", "")
    if isinstance(version, bool) or not isinstance(version, int):
        raise BundleError(f"bundle.json: schema_version = {_short(version)} must be an integer")
    if version not in READABLE_SCHEMAS:
        fix = "upgrade crossing_assist" if version > SCHEMA_VERSION else "re-export the bundle"
        raise BundleError(f"bundle.json: schema_version {version} unsupported (this package reads "
                          f"{', '.join(map(str, READABLE_SCHEMAS))}); {fix}")
    model_file = _get(meta, "model_file", "")
    if (not isinstance(model_file, str) or not model_file.endswith(".onnx") or Path(model_file).name != model_file
            or len(model_file) > MAX_NAME or "\x00" in model_file or model_file.startswith(".")):
        raise BundleError(f"bundle.json: model_file = {_short(model_file)} must be a plain file name ending in "
                          f".onnx (at most {MAX_NAME} characters)")
    mc = _get(meta, "mc", "")
    sha, size = meta.get("model_sha256", ""), meta.get("model_size", 0)
    if need_bytes:
        sha, size = _get(meta, "model_sha256", ""), _get(meta, "model_size", "")
        if not isinstance(sha, str) or len(sha) != 64 or any(ch not in "0123456789abcdef" for ch in sha):
            raise BundleError(f"bundle.json: model_sha256 = {_short(sha)} is not a lowercase hex SHA-256")
        size = _int(size, "model_size", MIN_ONNX_BYTES, MAX_ONNX_BYTES)
    fov = _num(_get(meta, "fov_deg", ""), "fov_deg", 0.0, 180.0, lo_open=True, hi_open=True)
    return Bundle(
        dir=Path(bundle_dir),
        schema_version=version,
        model_file=model_file,
        actions=_parse_actions(_get(meta, "actions", "")),
        fov_deg=fov,
        input=_parse_input(_get(meta, "input", "")),
        mc=McSpec(samples=_int(_get(mc, "samples", "mc"), "mc.samples", 1, 1024),
                  p=_num(_get(mc, "p", "mc"), "mc.p", 0.0, 1.0, hi_open=True),
                  mirror=_bool(mc.get("mirror", False), "mc.mirror"),
                  members=_int(mc.get("members", 1), "mc.members", 1, 64)),
        calibration=_parse_calibration(_get(meta, "calibration", "")),
        precision=_choice(_get(meta, "precision", ""), "precision", PRECISIONS),
        training=_obj(_get(meta, "training", ""), "training"),
        metrics=_obj(_get(meta, "metrics", ""), "metrics"),
        package_version=_str(_get(meta, "package_version", ""), "package_version"),
        provenance=_obj(_get(meta, "provenance", ""), "provenance"),
        model_sha256=sha,
        model_size=size,
        geometry=_parse_geometry(meta.get("geometry") if version >= 2 else None, fov, version),
        raw=dict(meta),
    )


# ----------------------------------------------------------------------------- read / write


def _check_model_file(path: Path, size: int, sha: str, *, verify_hash: bool) -> None:
    if not path.is_file():
        raise BundleError(f"bundle: model file {path} is missing; copy the whole bundle folder or re-export it")
    actual = path.stat().st_size
    if actual != size:
        raise BundleError(f"bundle: {path.name} has {actual} bytes but bundle.json says {size} "
                          "(truncated or replaced); copy the bundle again or re-export it")
    with open(path, "rb") as f:
        head = f.read(1)
        # An ONNX ModelProto starts with field 1 (ir_version, varint): tag byte 0x08.
        if head != b"\x08":
            raise BundleError(f"bundle: {path.name} is not an ONNX model (bad first byte); re-export the bundle")
        if verify_hash:
            f.seek(0)
            digest = hashlib.sha256()
            for chunk in iter(lambda: f.read(1 << 20), b""):
                digest.update(chunk)
            if digest.hexdigest() != sha:
                raise BundleError(f"bundle: {path.name} SHA-256 differs from bundle.json (corrupt or replaced); "
                                  "copy the bundle again or re-export it")


def _no_constant(name: str):
    raise ValueError(f"{name} is not JSON (the phone app cannot parse it)")


def read_bundle(bundle_dir: str | os.PathLike, *, verify_hash: bool = True) -> Bundle:
    """Read and validate a bundle folder; raises :class:`BundleError` (one line) when unusable.

    Checks every json field, that the action names/bins match :mod:`crossing_assist.actions`,
    and that the model file exists with the recorded size, ONNX framing and SHA-256.
    """
    root = Path(bundle_dir)
    if not root.is_dir():
        raise BundleError(f"bundle: {root} is not a folder; pass the folder holding bundle.json and model.onnx")
    jpath = root / BUNDLE_JSON
    if not jpath.is_file():
        raise BundleError(f"bundle: {jpath} is missing; pass a folder written by crossing-export")
    if jpath.stat().st_size > MAX_JSON_BYTES:
        raise BundleError(f"bundle: {jpath} is {jpath.stat().st_size} bytes (at most {MAX_JSON_BYTES}); "
                          "re-export the bundle")
    try:
        meta = json.loads(jpath.read_text(encoding="utf-8"), parse_constant=_no_constant)   # the app's JSON.parse
    except (UnicodeDecodeError, ValueError) as exc:  # JSONDecodeError, or an int over the digit limit
        raise BundleError(f"bundle: {jpath} is not valid JSON ({exc.__class__.__name__}: "
                          f"{_short(str(exc).splitlines()[0] if str(exc) else '', 120)}); re-export the bundle") from None
    except RecursionError:
        raise BundleError(f"bundle: {jpath} is nested too deeply to be a bundle.json; re-export the bundle") from None
    bundle = parse_meta(meta, root)
    _check_model_file(bundle.model_path, bundle.model_size, bundle.model_sha256, verify_hash=verify_hash)
    return bundle


def _strict(value: Any) -> Any:
    """NaN and infinities become null, recursively: bundle.json is strict JSON (the phone's
    ``JSON.parse`` refuses ``NaN``)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value


def embedded_meta(meta: Mapping[str, Any]) -> dict[str, Any]:
    """The bundle.json dict without the fields that depend on the model bytes (for metadata_props),
    as strict JSON (non-finite numbers become null)."""
    return {k: _strict(v) for k, v in meta.items() if k not in BYTE_FIELDS}


def graph_metadata(meta: Mapping[str, Any]) -> dict[str, str]:
    """The ONNX ``metadata_props`` entries that carry a bundle's facts inside its graph:
    ``bundle_json`` (:func:`embedded_meta`, keys sorted) and ``schema_version``."""
    return {"bundle_json": json.dumps(embedded_meta(meta), sort_keys=True),
            "schema_version": str(meta["schema_version"])}


def schema_for(geometry: Geometry | None) -> int:
    """The schema version a bundle of ``geometry`` is written as: 1 without a geometry block, 4 with
    a ``view_zoom`` other than 1, else 3 (the oldest version that holds everything it says)."""
    if geometry is None:
        return 1
    return SCHEMA_VERSION if geometry.view_zoom != 1 else 3


def make_meta(*, n_actions: int, input: InputSpec, mc: McSpec, calibration: Calibration,
              geometry: Geometry | None, precision: str = "fp32", training: Mapping[str, Any] | None = None,
              metrics: Mapping[str, Any] | None = None, provenance: Mapping[str, Any] | None = None,
              model_file: str = MODEL_FILE) -> dict[str, Any]:
    """The bundle.json dict (without the byte fields, which :func:`write_bundle` adds) from typed
    parts: the one place that lays bundle metadata out. ``geometry=None`` writes a schema-1
    bundle (stretched frames, one FOV of 90 degrees), which readers still accept; otherwise the
    current schema, whose ``fov_deg`` is the landscape camera FOV. Validated before it is returned."""
    meta: dict[str, Any] = {
        "schema_version": schema_for(geometry),
        "model_file": model_file,
        "actions": ActionsSpec.of(n_actions).to_json(),
        "fov_deg": DEFAULT_FOV_DEG if geometry is None else geometry.camera_fov_deg[0],
        "input": input.to_json(),
        "mc": mc.to_json(),
        "calibration": calibration.to_json(),
        "precision": precision,
        "training": dict(training or {}),
        "metrics": dict(metrics or {}),
        "package_version": __version__,
        "provenance": dict(provenance or {}),
    }
    if geometry is not None:
        meta["geometry"] = geometry.to_json()
    parse_meta(meta, need_bytes=False)
    return meta


def check_replaceable(bundle_dir: str | os.PathLike, *, force: bool = False) -> None:
    """Refuse to write a bundle over anything but nothing, an empty folder or a bundle (a folder
    holding only bundle.json and .onnx files): replacing a run folder, a dataset or a file would
    delete it. ``force=True`` allows it. Raises :class:`BundleError` (one line)."""
    root = Path(bundle_dir)
    if force or not (root.exists() or root.is_symlink()):
        return
    if not root.is_dir() or root.is_symlink():
        raise BundleError(f"bundle: {root} exists and is not a folder; pick a new --out or pass --force to "
                          "replace it")
    names = sorted(p.name for p in root.iterdir())
    if not names:
        return
    foreign = [n for n in names if n != BUNDLE_JSON and not n.endswith(".onnx")]
    if foreign or BUNDLE_JSON not in names:
        shown = ", ".join((foreign or names)[:4]) + (", ..." if len(foreign or names) > 4 else "")
        raise BundleError(f"bundle: {root} exists and is not a bundle (holds {shown}); replacing it would "
                          "delete that: pick a new --out or pass --force")


def write_bundle(bundle_dir: str | os.PathLike, onnx_bytes: bytes, meta: Mapping[str, Any], *,
                 force: bool = False) -> Path:
    """Write ``model.onnx`` + ``bundle.json`` atomically and return the folder.

    ``meta`` is the bundle.json dict; ``model_sha256`` and ``model_size`` are computed here. The
    bundle is written to a temporary sibling folder, validated with :func:`read_bundle`, then
    renamed into place. An existing bundle (or empty folder) there is replaced; anything else is
    refused unless ``force`` (see :func:`check_replaceable`). Only whole bundles are visible, and
    temporary folders a killed writer left beside it are swept first.
    """
    from crossing_assist.fileio import sweep_orphans, tmp_tag

    root = Path(bundle_dir)
    full = dict(embedded_meta(meta))
    full["model_sha256"] = hashlib.sha256(onnx_bytes).hexdigest()
    full["model_size"] = len(onnx_bytes)
    parse_meta(full, root)  # refuse bad metadata before touching the disk
    check_replaceable(root, force=force)
    root.parent.mkdir(parents=True, exist_ok=True)
    sweep_orphans(root.parent, prefix=f".{root.name}.")
    tmp = Path(tempfile.mkdtemp(prefix=f".{root.name}.{tmp_tag()}-", dir=root.parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes 0700; a bundle is an ordinary folder
    try:
        with open(tmp / full["model_file"], "wb") as f:
            f.write(onnx_bytes)
            f.flush()
            os.fsync(f.fileno())
        with open(tmp / BUNDLE_JSON, "w", encoding="utf-8") as f:
            json.dump(full, f, indent=2, allow_nan=False)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        read_bundle(tmp)
        old = None
        if root.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{root.name}.old{os.getpid()}-", dir=root.parent))
            os.replace(root, old / root.name)
        os.replace(tmp, root)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return root


# ----------------------------------------------------------------------------- graph vs json


_ABSENT = object()


def _first_difference(a: Any, b: Any, path: str) -> tuple[str, Any, Any] | None:
    """The first leaf (in ``a``'s key order, then ``b``'s other keys; list items in order) where two JSON
    values differ under ``==``: ``(path, a, b)`` with ``_ABSENT`` for a missing key or item, or None.
    The app's bundle.js ``firstDifference`` is the same walk."""
    if isinstance(a, dict) and isinstance(b, dict):
        pairs = ((f"{path}.{k}", a.get(k, _ABSENT), b.get(k, _ABSENT)) for k in [*a, *(k for k in b if k not in a)])
    elif isinstance(a, list) and isinstance(b, list):
        pairs = ((f"{path}[{i}]", a[i] if i < len(a) else _ABSENT, b[i] if i < len(b) else _ABSENT)
                 for i in range(max(len(a), len(b))))
    else:
        return None if a == b else (path, a, b)
    return next(filter(None, (_first_difference(x, y, p) for p, x, y in pairs)), None)


def _show(value: Any) -> str:
    """A JSON value for an error line, cut to 60 characters (``absent`` for a missing one)."""
    text = "absent" if value is _ABSENT else json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_session(bundle: Bundle, session: Any) -> None:
    """Check an onnxruntime ``InferenceSession`` of ``bundle.model_path`` against the json.

    Compares the input name/dtype, output names, the action dimension where the graph states
    it, and the bundle facts embedded in the model's metadata (:data:`EMBEDDED_KEYS`). Raises
    :class:`BundleError` with one line on the first mismatch; a fact that differs is named down to
    its first differing leaf, with both values (``bundle.json: calibration.uncertainty.threshold =
    0.05 disagrees with the model's 0.0135; re-export the bundle``).
    """
    inputs = session.get_inputs()
    if len(inputs) != 1 or inputs[0].name != INPUT_NAME or inputs[0].type != "tensor(uint8)":
        got = [(i.name, i.type) for i in inputs]
        raise BundleError(f"bundle: graph input {got} disagrees with the json (one uint8 input "
                          f"'{INPUT_NAME}'); re-export the bundle")
    outputs = {o.name: o for o in session.get_outputs()}
    missing = [n for n in OUTPUT_NAMES if n not in outputs]
    if missing:
        raise BundleError(f"bundle: graph lacks outputs {missing}; re-export the bundle")
    a_dim = outputs["probs"].shape[-1] if outputs["probs"].shape else None
    if isinstance(a_dim, int) and a_dim != bundle.actions.n:
        raise BundleError(f"bundle: graph has {a_dim} actions but bundle.json says {bundle.actions.n}; "
                          "re-export the bundle")
    props = dict(session.get_modelmeta().custom_metadata_map)
    if "bundle_json" not in props:
        raise BundleError("bundle: the graph has no 'bundle_json' metadata; re-export the bundle")
    try:
        graph_meta = json.loads(props["bundle_json"])
    except json.JSONDecodeError:
        graph_meta = None
    if not isinstance(graph_meta, dict):
        raise BundleError("bundle: the graph's 'bundle_json' metadata is not a JSON object; re-export the bundle")
    mine = embedded_meta(bundle.raw)
    for key in EMBEDDED_KEYS:
        if graph_meta.get(key) != mine.get(key):
            path, ours, theirs = (_first_difference(mine.get(key), graph_meta.get(key), key)
                                  or (key, mine.get(key), graph_meta.get(key)))  # (a safety net)
            raise BundleError(f"bundle.json: {path} = {_show(ours)} disagrees with the model's {_show(theirs)}; "
                              "re-export the bundle")

