"""Frames -> normalised tensors, and the fixed augmentation *variants* of each frame.

A variant is ``(mirrored, yaw_deg, field)``: the frame flipped left-right (bin k -> 13 - k)
and/or re-rendered as if the camera had turned by ``yaw_deg`` (an exact homography; the label
moves predictably, goals turned out of the frame become ``unknown``); ``field >= 0`` instead
draws a *field view* (:func:`crossing_assist.data_tools.augment.field_view`: mirror, roll, a
phone aspect, a corruption) from a generator seeded by (seed, field, image path). Variants
are fixed (not random per epoch) so that frozen-backbone features can be computed once and
cached.

Every variant is then fitted to the canvas as the bundle's graph will fit a camera frame:
``letterbox`` (:mod:`crossing_assist.geometry`; the frame's content window on the canvas is
returned with it) or ``stretch`` (the schema-1 way).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

import zlib

from ..actions import UNKNOWN
from ..data_tools import augment
from ..data_tools.images import ImageError, flag_value, load_frame, load_rgb
from ..data_tools.manifest import Dataset, Row
from ..geometry import PAD_RGB, GeometryError, content_window, letterbox, letterbox_geometry, take_rows


@dataclass(frozen=True)
class Variant:
    """One fixed augmentation: flip first (if ``mirrored``), then yaw by ``yaw_deg`` (right +)."""

    mirrored: bool = False
    yaw_deg: float = 0.0
    field: int = -1          # >= 0: the field-th random field view (mirror/yaw unused)
    without: tuple[str, ...] = ()   # field-view steps left out (an ablation; augment.field_view)
    zoom: float = 1.0               # > 1: field views may be magnified up to this (augment.field_view)

    @property
    def tag(self) -> str:
        if self.field >= 0:
            return f"field{self.field}"
        return f"{'m' if self.mirrored else 'o'}{self.yaw_deg:+g}"


def make_variants(mirror: bool, yaw_angles: tuple[float, ...] = (), field: int = 0,
                  field_without: tuple[str, ...] = (), field_zoom: float = 1.0) -> tuple[Variant, ...]:
    """Identity (+ mirrored) x (0 and +-each yaw angle), then ``field`` random field views
    (``field_without``: their steps left out; ``field_zoom``: their largest magnification);
    identity first."""
    flips = (False, True) if mirror else (False,)
    angles = (0.0,) + tuple(s * float(a) for a in yaw_angles for s in (1, -1) if a)
    return (tuple(Variant(f, a) for f in flips for a in angles)
            + tuple(Variant(field=i, without=tuple(field_without), zoom=float(field_zoom)) for i in range(field)))


def resize_rgb(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """H x W x 3 uint8 -> size (H, W) x 3 uint8; area filter when shrinking, bilinear else."""
    h, w = size
    if image.shape[:2] == (h, w):
        return image
    shrink = image.shape[0] > h or image.shape[1] > w
    return cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def normalise(images: np.ndarray, mean: tuple[float, ...], std: tuple[float, ...]) -> np.ndarray:
    """N x H x W x 3 uint8 RGB -> N x 3 x H x W float32, ``(x / 255 - mean) / std``."""
    x = images.astype(np.float32) / 255.0
    x = (x - np.asarray(mean, np.float32)) / np.asarray(std, np.float32)
    return np.ascontiguousarray(x.transpose(0, 3, 1, 2))


def apply_variant(image: np.ndarray, far_x: float | None, label: int, v: Variant,
                  fov_deg: float) -> tuple[np.ndarray, float | None, int]:
    """The variant of a (resized) frame with its moved goal and bin (0 = unknown)."""
    if v.mirrored:
        image, far_x, label = augment.mirror(image, far_x, label)
    if v.yaw_deg:
        image, far_x, label, _ = augment.yaw(image, far_x, label, v.yaw_deg, fov_deg=fov_deg,
                                             out_of_frame="unknown")
    return image, far_x, label


def _field_rng(seed: int, field: int, image: str) -> np.random.Generator:
    return np.random.default_rng([seed, field, zlib.crc32(image.encode())])


def load_variants(ds: Dataset, row: Row, size: tuple[int, int], variants: tuple[Variant, ...],
                  fov_deg: float, fit: str = "stretch", seed: int = 0,
                  ) -> list[tuple[np.ndarray, float, int, tuple[float, float]]]:
    """Every variant of one row, fitted to the canvas ``size`` (H, W): (image H x W x 3 uint8,
    far_x or nan, bin, content window (x0, x1) as fractions of the canvas width)."""
    out = []
    if fit == "stretch":
        base = resize_rgb(load_rgb(ds.image_path(row)), size)
        for v in variants:
            img, fx, lab = apply_variant(base, row.far_x, row.label, v, fov_deg)
            out.append((img, np.nan if fx is None or lab == UNKNOWN else float(fx), int(lab), (0.0, 1.0)))
        return out
    # the rows the runtime will give the graph: a portrait frame (a researcher's own, or a
    # portrait no-crossing view) loses the rows beyond the training camera's view, as
    # Engine.predict crops them, so it is learned at the scale it is served (4:3 keeps them all)
    zoom = max((v.zoom for v in variants if v.field >= 0), default=1.0)
    path = ds.image_path(row)
    frame = load_frame(path, row.flags)
    geo, (fh, fw) = letterbox_geometry(fov_deg, view_zoom=zoom), frame.shape[:2]
    try:
        top, rows = geo.camera_rows(fh, fw, size)   # as geo.camera_view takes them (crop or pad)
    except GeometryError as exc:
        raise ImageError(f"{path}: {exc}") from None
    base = take_rows(frame, top, rows, geo.pad_rgb)
    far_y = flag_value(row.flags, "far_y")   # a fraction of the frame's height: of the rows kept
    far_y = 0.5 if far_y is None else (float(far_y) * fh - top) / rows
    scale = 2 * max(size) / max(base.shape[:2])
    if scale < 1:  # keep a margin over the canvas for crops, but do not warp megapixels
        base = resize_rgb(base, (max(8, round(base.shape[0] * scale)), max(8, round(base.shape[1] * scale))))
    for v in variants:
        if v.field >= 0:
            img, fx, lab, _ = augment.field_view(base, row.far_x, far_y, row.label, _field_rng(seed, v.field, row.image),
                                                  v.without, v.zoom)
        else:
            img, fx, lab = apply_variant(base, row.far_x, row.label, v, fov_deg)
        window = content_window(img.shape[0], img.shape[1], size)
        out.append((letterbox(img, size, PAD_RGB), np.nan if fx is None or lab == UNKNOWN else float(fx),
                    int(lab), window))
    return out
