"""Camera geometry: how a frame of any size meets the model's canvas, and which field of view
turns its strips into headings (numpy + OpenCV; no torch).

The model sees a fixed canvas (``H x W``, e.g. 168 x 224, a 4:3 landscape like the PTL photos).
A frame of another aspect is *letterboxed*: scaled to fit inside the canvas without stretching,
centred, the rest filled with ``pad_rgb``. The integer arithmetic of :func:`letterbox_box` is
the contract: the exported ONNX graph (``export/graph.py``) computes the same box from the
frame's height and width, so training, Python and the phone fit frames identically.

The 12 strips are strips of the *frame* (the camera's view), not of the padded canvas; the
head samples its per-column scores inside the content window :func:`content_window`. A goal
that is out of view but inferable lies in an edge strip (1 or 12), so the padding never holds a
strip: an edge strip means "at or beyond that edge of the view".

Headings use the horizontal field of view of the camera that took the frame in its present
orientation (:meth:`Geometry.camera_fov`), never a constant. The bundle's default is per
orientation (``camera_fov_deg``, the full sensor); with ``sensor_aspect`` (long side / short side
of that sensor) a frame narrower than the sensor in its orientation is a crop of it and gets the
crop's FOV (9:16 portrait video: ~41 deg across, not 53; :func:`default_fov`).

The *view crop* (``Geometry.view_crop``, bundle schema 3) keeps the model's angular scale: the
canvas shows the training camera's view (``train_fov_deg`` across its width, 4:3), so a frame
from a camera of horizontal FOV ``f`` first loses the rows above and below what that canvas can
show at the training photos' pixels per degree (:func:`view_rows`), then is letterboxed. A phone
held in portrait (3:4, ~53 deg across) keeps its middle ~3:3 at the training scale instead of
being shrunk to 3/4 of it with sky and feet added; a 4:3 landscape frame at the training FOV, a
16:9 video frame, or a narrower portrait camera lose nothing. A narrower camera's frame that is
shorter than that view (a landscape camera zoomed in, or set narrower than its sensor's FOV) gets
rows of ``pad_rgb`` above and below instead: letterboxed as it is, it would fill the canvas
magnified (:func:`take_rows`). Columns are never cropped: the 12 strips span the whole frame.

*Levelling* (:func:`level`): a phone is rarely held level. Where its orientation sensor says how
far the camera is rolled about its own axis, the frame is turned back by that roll (at most
``MAX_LEVEL_DEG``) before anything else, so the model sees the horizon level, as in the training
photos, and the frame's columns are bearings again; the corners the tilted camera did not see
are filled with ``pad_rgb``. The phone app does the same on its canvas (``camera.js``).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np

FITS = ("letterbox", "stretch")
ORIENTATIONS = ("landscape", "portrait")
#: Typical phone main camera (4:3 sensor, ~26 mm equivalent): ~67 deg across the long side,
#: ~53 deg across the short side. Used when neither the user nor the device says otherwise.
CAMERA_FOV_DEG = {"landscape": 67.0, "portrait": 53.0}
#: The horizontal field of view assumed for the PTL training photos (phone cameras, landscape).
TRAIN_FOV_DEG = 67.0
FOV_RANGE_DEG = (20.0, 170.0)
#: Two horizontal FOVs this close (degrees) are one camera (a 26 mm photo's 67.3 is the training 67).
SAME_CAMERA_DEG = 1.0
#: Long side / short side of the sensor ``camera_fov_deg`` describes (a phone's 4:3 main camera);
#: the exporter writes it as ``geometry.sensor_aspect`` for letterbox models.
SENSOR_ASPECT = 4 / 3
SENSOR_ASPECT_RANGE = (1.0, 3.0)
DEFAULT_CANVAS = (168, 224)            # (H, W): 4:3 landscape
PAD_RGB = (124, 116, 104)              # ImageNet mean in uint8: normalises to ~0
MAX_ASPECT = 8.0                       # frames more elongated than 8:1 are refused
VIEW_ZOOM_RANGE = (1.0, 4.0)           # geometry.view_zoom (schema 4): 1 = the training scale
#: The most a frame is turned back to level (degrees): a phone rolled further is levelled by this
#: much (the phone's screen turns by a quarter at about 45 deg, so its frames rarely roll more).
MAX_LEVEL_DEG = 45.0
MIN_LEVEL_DEG = 0.5   # a smaller roll is left alone
#: A frame rolled further than this gets no guidance: levelled by MAX_LEVEL_DEG it stays rolled
#: by more than the 15 deg training views roll. Held out (PTL val, the default bundle, sensor
#: levelling): rolled 45-60 deg 81.5 % on at 0.5 % confidently wrong; 60-90 deg 74 % on at 4 %
#: (scripts/roll_levelling.py --rolls 45:60,60:90, 200 photos; a phone turned sideways with the
#: screen's rotation locked).
MAX_GUIDED_ROLL_DEG = MAX_LEVEL_DEG + 15.0


#: :func:`view_rows` pads a frame only when it is more than 1 / PAD_SLACK shorter than the view.
PAD_SLACK = 50


def view_rows(height: int, width: int, fov_deg: float, canvas: tuple[int, int],
              train_fov_deg: float = TRAIN_FOV_DEG, zoom: float = 1.0) -> tuple[int, int]:
    """The rows of a ``height x width`` frame (horizontal FOV ``fov_deg``) that the canvas shows
    at the training camera's angular scale (``zoom`` = 1), or magnified by up to ``zoom``:
    ``(top, rows)``, centred; ``rows`` > ``height`` (``top`` < 0) means rows of padding added
    above and below (:func:`take_rows`).

    ``rows = max(1, floor(width * H * t / W + 0.5))`` for the canvas (H, W), with
    ``t = max(1, tan(train / 2) / tan(fov / 2) / zoom)``, and at most ``height`` when ``t`` = 1 or
    when it exceeds ``height`` by at most ``height // PAD_SLACK`` rows (a crop of the sensor, e.g. a
    3:4 window of a photo at its own FOV, is the view's height but for rounding: no padding);
    ``top = (height - rows) // 2``. A camera wider than the training one (``t`` would be < 1)
    cannot reach the training scale without losing columns, so its frame is fitted by its width and
    keeps the rows the canvas shows at that scale. A narrower camera's frame is shown
    ``min(tan(train / 2) / tan(fov / 2), zoom)`` times magnified (a large zoom: its middle rows fill
    the canvas): cropped to those rows when taller, padded to them when shorter (a landscape frame
    zoomed in, which letterboxed as it is would fill the canvas magnified further). The phone app
    computes the same (android_demo/www/js/geometry.js); the shared test vectors hold both to it."""
    ch, cw = canvas
    t = max(1.0, math.tan(math.radians(train_fov_deg) / 2) / math.tan(math.radians(fov_deg) / 2) / zoom)
    rows = max(1, math.floor(width * ch * t / cw + 0.5))
    if t == 1.0 or rows <= height + height // PAD_SLACK:   # a frame the view's height, to rounding: as it is
        rows = min(int(height), rows)
    return (int(height) - rows) // 2, rows


def take_rows(frame: np.ndarray, top: int, rows: int, pad_rgb: tuple[int, int, int] = PAD_RGB) -> np.ndarray:
    """``rows`` rows of an H x W x C frame from row ``top`` (:func:`view_rows`): a view of the frame
    when they lie inside it, else a copy with the rows beyond it filled with ``pad_rgb``."""
    h = frame.shape[0]
    if 0 <= top and top + rows <= h:
        return frame[top:top + rows]
    out = np.empty((rows,) + frame.shape[1:], frame.dtype)
    out[:] = np.asarray(pad_rgb, frame.dtype)
    lo, hi = max(0, top), min(h, top + rows)
    out[lo - top:hi - top] = frame[lo:hi]
    return out


def window_fov(fraction: float, fov_deg: float) -> float:
    """Horizontal FOV (degrees) of a centred window covering ``fraction`` of the width of a frame
    whose horizontal FOV is ``fov_deg`` (pinhole: the tangents scale). An off-centre window of the
    same width spans less: a 3:4 window at the edge of a 67 deg 4:3 photo 38.2 deg, not 40.8; read
    as a centred camera of 40.8 deg, its headings are off by 0.2 deg on average and 3 deg at most
    (crossing-eval's windows at the photo's edges)."""
    return math.degrees(2 * math.atan(fraction * math.tan(math.radians(fov_deg) / 2)))


class GeometryError(ValueError):
    """A frame or field of view the geometry cannot use (one line, says what is valid)."""


def default_fov(width: int, height: int, camera_fov_deg: tuple[float, float],
                sensor_aspect: float | None = None) -> float:
    """The default horizontal FOV (degrees, unchecked) of a ``width x height`` frame:
    ``camera_fov_deg`` (landscape, portrait) of its :func:`orientation`; with ``sensor_aspect``
    (long / short side of that sensor), a frame narrower than the sensor in its orientation is a
    centred crop of it: with ``full = sensor_aspect`` (landscape) or ``1 / sensor_aspect``
    (portrait) and ``a = width / height``, ``a < full`` gives ``window_fov(a / full, fov)``.
    E.g. 67/53 deg and 4:3: 1080 x 1920 (9:16) -> ~41.0 deg, 1:1 -> ~52.8 deg; 3:4, 4:3 and
    16:9 keep theirs. The phone app computes the same (android_demo/www/js/geometry.js)."""
    o = orientation(width, height)
    fov = camera_fov_deg[ORIENTATIONS.index(o)]
    if sensor_aspect is not None:
        full = sensor_aspect if o == "landscape" else 1 / sensor_aspect
        a = width / height
        if a < full:
            fov = window_fov(a / full, fov)
    return fov


def parse_ratio(text: str) -> float:
    """``W:H`` (e.g. ``4:3``, ``3:4``) as the positive number W / H; ValueError otherwise."""
    w, sep, h = str(text).partition(":")
    ratio = float(w) / float(h) if sep and float(h) != 0 else math.nan
    if not ratio > 0 or math.isinf(ratio):
        raise ValueError(f"not a ratio W:H of positive numbers: {text!r}")
    return ratio


def check_sensor_aspect(value: float) -> float:
    """A sensor aspect (long side / short side) in 1..3, as float; else GeometryError (one line)."""
    lo, hi = SENSOR_ASPECT_RANGE
    try:
        aspect = float(value)
    except (TypeError, ValueError):
        aspect = math.nan
    if isinstance(value, bool) or not lo <= aspect <= hi:
        raise GeometryError(f"Invalid sensor aspect: {value!r}; valid: long side / short side in {lo:g}..{hi:g} "
                            "(e.g. 1.3333333333333333 for a 4:3 sensor)")
    return aspect


@dataclass(frozen=True)
class Geometry:
    """The bundle's geometry contract (``bundle.json`` ``geometry``).

    ``fit``: ``letterbox`` (scale to fit, centre, pad with ``pad_rgb``) or ``stretch`` (schema 1:
    resize to the canvas whatever the aspect); ``camera_fov_deg``: default horizontal FOV per
    orientation; ``train_fov_deg``: the FOV assumed for the training photos; ``view_crop``
    (schema 3): crop the rows beyond the training camera's view before fitting (:func:`view_rows`);
    ``sensor_aspect`` (optional, 1..3; None = absent): long side / short side of the sensor
    ``camera_fov_deg`` describes, so narrower frames get their crop's FOV (:func:`default_fov`);
    ``view_zoom`` (schema 4, 1..4, with ``view_crop``): a frame from a camera narrower than the
    training one is shown magnified by up to this much instead of at the training scale (for a
    model trained on magnified views, ``crossing-train --field-zoom``); 1 = the training scale.
    """

    fit: str = "letterbox"
    pad_rgb: tuple[int, int, int] = PAD_RGB
    camera_fov_deg: tuple[float, float] = (CAMERA_FOV_DEG["landscape"], CAMERA_FOV_DEG["portrait"])
    train_fov_deg: float = TRAIN_FOV_DEG
    view_crop: bool = False
    sensor_aspect: float | None = None
    view_zoom: float = 1.0

    def __post_init__(self) -> None:
        lo, hi = VIEW_ZOOM_RANGE
        if not lo <= self.view_zoom <= hi:
            raise GeometryError(f"Invalid view zoom: {self.view_zoom!r}; valid: {lo:g}..{hi:g} (1 = the training scale)")
        if self.view_zoom != 1 and not self.view_crop:
            raise GeometryError(f"Invalid view zoom: {self.view_zoom:g} needs the view crop (geometry.view_crop)")

    def to_json(self) -> dict:
        d = {"fit": self.fit, "strips": "frame",
             "camera_fov_deg": {"landscape": self.camera_fov_deg[0], "portrait": self.camera_fov_deg[1]},
             "train_fov_deg": self.train_fov_deg}
        if self.fit == "letterbox":
            d["pad_rgb"] = list(self.pad_rgb)
            d["view_crop"] = self.view_crop
        if self.view_zoom != 1:   # schema 4; schema-3 geometries are written as before
            d["view_zoom"] = self.view_zoom
        if self.sensor_aspect is not None:
            d["sensor_aspect"] = self.sensor_aspect
        return d

    def rows_seen(self, height: int, width: int, fov_deg: float, canvas: tuple[int, int]) -> tuple[int, int]:
        """``(top, rows)`` of a ``height x width`` frame (horizontal FOV ``fov_deg``) that the graph
        sees: :func:`view_rows` (magnified up to ``view_zoom``) with ``view_crop``, else all of them."""
        if not self.view_crop:
            return 0, int(height)
        return view_rows(height, width, fov_deg, canvas, self.train_fov_deg, self.view_zoom)

    def view(self, frame: np.ndarray, fov_deg: float, canvas: tuple[int, int]) -> np.ndarray:
        """The part of an H x W x C frame (horizontal FOV ``fov_deg``) the graph should see
        (:meth:`rows_seen`: a view of its rows, or a padded copy, :func:`take_rows`; the frame
        itself without ``view_crop``)."""
        if not self.view_crop:
            return frame
        return take_rows(frame, *self.rows_seen(frame.shape[0], frame.shape[1], fov_deg, canvas), self.pad_rgb)

    def camera_view(self, frame: np.ndarray, canvas: tuple[int, int], fov_deg: float | None = None) -> np.ndarray:
        """:meth:`view` at the frame's camera FOV (:meth:`camera_fov`): what a consumer gives the
        graph for a frame of any orientation, as ``Engine.predict`` does. GeometryError for a
        frame too narrow for any camera."""
        return take_rows(frame, *self.camera_rows(frame.shape[0], frame.shape[1], canvas, fov_deg), self.pad_rgb)

    def camera_rows(self, height: int, width: int, canvas: tuple[int, int],
                    fov_deg: float | None = None) -> tuple[int, int]:
        """``(top, rows)`` :meth:`camera_view` keeps of a ``height x width`` frame."""
        return self.rows_seen(height, width, self.camera_fov(width, height, fov_deg), canvas)

    def camera_fov(self, width: int, height: int, override: float | None = None) -> float:
        """Horizontal FOV (degrees) for a ``width x height`` frame: ``override`` (the user's or the
        device's) as given, else the default for the frame's orientation and aspect
        (:func:`default_fov`). Raises GeometryError outside 20..170 degrees."""
        if override is not None:
            return check_fov(override)
        return check_fov(default_fov(width, height, self.camera_fov_deg, self.sensor_aspect))


def letterbox_geometry(train_fov_deg: float = TRAIN_FOV_DEG, pad_rgb: tuple[int, int, int] = PAD_RGB,
                       view_zoom: float = 1.0) -> Geometry:
    """The geometry a letterbox model's bundle carries: the view crop (schema 3), the phone
    sensor's aspect for frames narrower than it, the default camera FOVs; ``view_zoom`` (schema 4)
    for models trained on magnified views. The exporter writes it; training shows each frame
    through it (:meth:`Geometry.camera_view`), so both see the rows the runtime will."""
    return Geometry(fit="letterbox", pad_rgb=tuple(pad_rgb), train_fov_deg=train_fov_deg, view_crop=True,
                    sensor_aspect=SENSOR_ASPECT, view_zoom=view_zoom)


def orientation(width: int, height: int) -> str:
    """``portrait`` if the frame is taller than wide, else ``landscape``."""
    return "portrait" if height > width else "landscape"


def check_fov(fov_deg: float) -> float:
    """A horizontal field of view in the sane range 20..170 degrees, as float."""
    try:
        fov = float(fov_deg)
    except (TypeError, ValueError):
        raise GeometryError(f"Invalid field of view: {fov_deg!r}; valid: 20..170 degrees") from None
    lo, hi = FOV_RANGE_DEG
    if not lo <= fov <= hi:
        raise GeometryError(f"Invalid field of view: {fov_deg} degrees; valid: {lo:g}..{hi:g}")
    return fov


#: How a size is typed on a command line -> an example.
SIZE_ORDERS = {"HxW": "168x224", "WxH": "320x240"}


def parse_size(text: str, typed: str = "HxW") -> tuple[int, int]:
    """A size typed on a command line, returned as ``(height, width)``: the package's one order
    (numpy's, :data:`DEFAULT_CANVAS`'s, ``input_size``'s).

    ``typed`` says how the user writes it: ``"HxW"`` for a model canvas
    (``crossing-train --input-size 168x224``, like ``input_size``), ``"WxH"`` for a frame or a
    video, as screens are named (``crossing-data synth --size 320x240``). One number is a
    square. An argparse ``type``: raises ``argparse.ArgumentTypeError`` (one line) otherwise.
    """
    example = SIZE_ORDERS[typed]
    try:
        parts = [int(v) for v in text.lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) == 1:
        parts *= 2
    if len(parts) != 2 or min(parts) < 1:
        raise argparse.ArgumentTypeError(f"size {text!r} invalid; expected {typed} in pixels (or one number "
                                         f"for a square), e.g. {example}")
    return (parts[0], parts[1]) if typed == "HxW" else (parts[1], parts[0])


def check_frame_shape(height: int, width: int) -> None:
    """Refuse frames the model cannot see sensibly: under 8 px a side, or over 8:1."""
    if min(height, width) < 8:
        raise GeometryError(f"Invalid frame: {width}x{height} px; valid: at least 8 px a side")
    if max(height, width) > MAX_ASPECT * min(height, width):
        raise GeometryError(f"Invalid frame: {width}x{height} px has an aspect beyond {MAX_ASPECT:g}:1")


def letterbox_box(height: int, width: int, canvas: tuple[int, int]) -> tuple[int, int, int, int]:
    """Where a ``height x width`` frame lands on the canvas (H, W): ``(top, left, new_h, new_w)``.

    ``new_w = min(W, round(w H / h))``, ``new_h = min(H, round(h W / w))`` (rounding half up, in
    integers), at least 1; the content is centred (``left = (W - new_w) // 2``). The ONNX graph
    uses exactly this arithmetic."""
    ch, cw = canvas
    new_w = max(1, min(cw, (width * ch * 2 + height) // (2 * height)))
    new_h = max(1, min(ch, (height * cw * 2 + width) // (2 * width)))
    return (ch - new_h) // 2, (cw - new_w) // 2, new_h, new_w


def content_window(height: int, width: int, canvas: tuple[int, int], fit: str = "letterbox") -> tuple[float, float]:
    """The frame's horizontal extent on the canvas, as fractions of the canvas width ``(x0, x1)``."""
    if fit == "stretch":
        return 0.0, 1.0
    _, left, _, new_w = letterbox_box(height, width, canvas)
    return left / canvas[1], (left + new_w) / canvas[1]


def letterbox(image: np.ndarray, canvas: tuple[int, int], pad_rgb: tuple[int, int, int] = PAD_RGB) -> np.ndarray:
    """Fit an H x W x 3 uint8 image onto the canvas (letterbox; area filter when shrinking)."""
    import cv2

    top, left, nh, nw = letterbox_box(image.shape[0], image.shape[1], canvas)
    shrink = image.shape[0] > nh or image.shape[1] > nw
    inner = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    out = np.empty((canvas[0], canvas[1], 3), np.uint8)
    out[:] = np.asarray(pad_rgb, np.uint8)
    out[top:top + nh, left:left + nw] = inner
    return out


def rolled_too_far(roll_deg: float | None) -> bool:
    """True when a roll reading (degrees) is beyond ``MAX_GUIDED_ROLL_DEG`` either way: the frame
    cannot be levelled into what the model learned, so it gets no guidance."""
    return roll_deg is not None and math.isfinite(roll_deg) and abs(roll_deg) > MAX_GUIDED_ROLL_DEG


def level_angle(roll_deg: float | None) -> float:
    """The roll (degrees) :func:`level` turns a frame back by: ``roll_deg`` clamped to
    +-``MAX_LEVEL_DEG``; 0 under ``MIN_LEVEL_DEG`` or without a reading (None, not finite)."""
    if roll_deg is None or not math.isfinite(roll_deg) or abs(roll_deg) < MIN_LEVEL_DEG:
        return 0.0
    return max(-MAX_LEVEL_DEG, min(MAX_LEVEL_DEG, float(roll_deg)))


def level(image: np.ndarray, roll_deg: float, pad_rgb: tuple[int, int, int] = PAD_RGB) -> np.ndarray:
    """``image`` (H x W x 3 uint8) as a level camera would have framed it: turned about its
    centre by ``-roll_deg`` (the scene's counter-clockwise roll in the frame, degrees; a phone
    turned clockwise rolls it counter-clockwise) as far as :func:`level_angle` says; the corners
    the camera did not see are ``pad_rgb``. Same size; bilinear. ``level(augment.roll(img, r), r)``
    is ``img`` inside the rolled camera's view. No turn (a small roll, no reading) returns
    ``image`` itself. The phone app's ``FrameGrabber.level`` (``camera.js``) draws the same."""
    angle = level_angle(roll_deg)
    if angle == 0:
        return image
    import cv2

    h, w = image.shape[:2]
    m = cv2.getRotationMatrix2D((w / 2 - 0.5, h / 2 - 0.5), -angle, 1.0)
    return cv2.warpAffine(np.ascontiguousarray(image), m, (w, h), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=tuple(int(v) for v in pad_rgb))


def window_x(far_x: float, x0: float, width: float) -> float:
    """A goal at ``far_x`` of a photo, seen through a window starting at ``x0`` of ``width``
    (fractions of the photo's width): its position in the window, clipped into the edge strips
    when out of view (``x' = (x - x0) / width``; out-of-view goals are inferable, so edge strip)."""
    x = (far_x - x0) / width
    return min(max(x, 1e-6), 1 - 1e-6)
