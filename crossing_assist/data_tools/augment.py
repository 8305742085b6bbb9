"""Augmentations whose labels stay exact: mirroring and yaw (a pure camera rotation).

Camera model
    A pinhole camera with horizontal field of view ``fov_deg`` (90° by default, the thesis's
    region in front of the user), square pixels and the principal point at the image centre.
    In pixel-index coordinates (pixel ``i`` covers ``[i - 0.5, i + 0.5]``) the intrinsics are
    ``fx = fy = (W / 2) / tan(fov / 2)``, ``cx = W / 2 - 0.5``, ``cy = H / 2 - 0.5``, so a goal at
    fraction ``x`` of the width has heading ``atan((2x - 1) tan(fov / 2))``, exactly
    :func:`crossing_assist.actions.x_to_heading`.

Yaw
    Turning the camera right by ``psi`` (degrees) maps old pixels to new pixels by the
    homography ``K R K^-1`` with ``R = [[cos psi, 0, -sin psi], [0, 1, 0], [sin psi, 0, cos psi]]``;
    a goal with heading ``h`` gets heading ``h - psi`` (it moves left). Output pixels whose ray
    falls outside the original photo (or behind the camera) are black and ``False`` in the
    returned mask. A goal that leaves the frame becomes ``unknown`` (``out_of_frame="unknown"``)
    or the edge bin 1 / 12 on the side it left by (``"edge"``, as the thesis's experts labelled
    a goal just outside the frame); in both cases ``far_x`` becomes None.

    Frames labelled with a bin but no ``far_x`` (human votes) move the bin's centre; the label
    is then exact only up to the strip's width.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from crossing_assist.actions import (
    DEFAULT_FOV_DEG, N_BINS, UNKNOWN, bin_center_x, heading_to_x, mirror_bin, mirror_x,
    parse_label, x_to_bin, x_to_heading,
)

from crossing_assist.geometry import PAD_RGB, window_fov, window_x

OUT_OF_FRAME_MODES = ("unknown", "edge")


def _check_image(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim not in (2, 3) or image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(f"Invalid image: expected H×W or H×W×C, got shape {image.shape}")
    return image


def mirror(image: np.ndarray, far_x: float | None, label: int) -> tuple[np.ndarray, float | None, int]:
    """Flip an H×W(×C) frame left-right: ``far_x -> 1 - far_x``, bin ``k -> 13 - k``.

    Returns a new contiguous array; unknown stays unknown.
    """
    image = _check_image(image)
    label = parse_label(label)
    return np.ascontiguousarray(image[:, ::-1]), (None if far_x is None else mirror_x(far_x)), mirror_bin(label)


def intrinsics(width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG) -> np.ndarray:
    """3×3 pinhole matrix K (pixel-index coordinates, square pixels) for a W×H frame."""
    if not 0 < fov_deg < 180:
        raise ValueError(f"Invalid field of view: {fov_deg} degrees; valid: 0 < fov < 180")
    f = (width / 2) / math.tan(math.radians(fov_deg) / 2)
    return np.array([[f, 0, width / 2 - 0.5], [0, f, height / 2 - 0.5], [0, 0, 1]], dtype=np.float64)


def yaw_rotation(psi_deg: float) -> np.ndarray:
    """3×3 rotation taking old camera coordinates (x right, y down, z forward) to those of a
    camera turned right by ``psi_deg``."""
    c, s = math.cos(math.radians(psi_deg)), math.sin(math.radians(psi_deg))
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]], dtype=np.float64)


def yaw_homography(width: int, height: int, psi_deg: float, fov_deg: float = DEFAULT_FOV_DEG) -> np.ndarray:
    """``K R K^-1``: maps homogeneous old pixel coordinates to the turned camera's pixels."""
    k = intrinsics(width, height, fov_deg)
    return k @ yaw_rotation(psi_deg) @ np.linalg.inv(k)


def yaw_x(x: float, psi_deg: float, fov_deg: float = DEFAULT_FOV_DEG) -> float | None:
    """Goal position after turning right by ``psi_deg``; None when it leaves the view.

    Values outside [0, 1] are returned as None too (the goal is outside the frame).
    """
    h = x_to_heading(x, fov_deg) - float(psi_deg)
    if not -90.0 < h < 90.0:
        return None
    x_new = heading_to_x(h, fov_deg)
    return x_new if 0.0 <= x_new <= 1.0 else None


def yaw_label(far_x: float | None, label: int, psi_deg: float, fov_deg: float = DEFAULT_FOV_DEG,
              out_of_frame: str = "unknown") -> tuple[float | None, int]:
    """The ``(far_x, label)`` of a frame re-rendered as if the user turned right by ``psi_deg``."""
    if out_of_frame not in OUT_OF_FRAME_MODES:
        raise ValueError(f"Unknown out_of_frame: {out_of_frame!r}; valid: {', '.join(OUT_OF_FRAME_MODES)}")
    label = parse_label(label)
    if label == UNKNOWN:
        return None, UNKNOWN
    x = far_x if far_x is not None else bin_center_x(label)
    x_new = yaw_x(x, psi_deg, fov_deg)
    if x_new is None:
        if out_of_frame == "unknown":
            return None, UNKNOWN
        went_left = x_to_heading(x, fov_deg) - psi_deg < 0
        return None, 1 if went_left else N_BINS
    return (x_new if far_x is not None else None), x_to_bin(x_new)


def _yaw_maps(width: int, height: int, psi_deg: float, fov_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source coordinates (map_x, map_y, float32 H×W) of each output pixel and the valid mask.

    The output pixel's ray ``r' = K^-1 (u, v, 1)`` comes from the old ray ``R^T r'``; for a
    rotation about the vertical axis its depth and source column depend on ``u`` only, so the
    maps are built from 1-D arrays (equivalent to applying ``(K R K^-1)^-1`` per pixel).
    """
    k = intrinsics(width, height, fov_deg)
    f, cx, cy = k[0, 0], k[0, 2], k[1, 2]
    c, s = math.cos(math.radians(psi_deg)), math.sin(math.radians(psi_deg))
    xn = (np.arange(width, dtype=np.float64) - cx) / f                   # (W,)
    yn = (np.arange(height, dtype=np.float64) - cy) / f                  # (H,)
    z = c - s * xn                                                       # old depth per column
    ahead = z > 1e-9
    zsafe = np.where(ahead, z, 1.0)
    sx = f * (c * xn + s) / zsafe + cx                                   # (W,)
    sy = f * yn[:, None] / zsafe[None, :] + cy                           # (H, W)
    valid = (ahead & (sx >= -0.5) & (sx <= width - 0.5))[None, :] & (sy >= -0.5) & (sy <= height - 0.5)
    map_x = np.where(valid, np.clip(sx, 0, width - 1)[None, :], -1).astype(np.float32)
    map_y = np.where(valid, np.clip(sy, 0, height - 1), -1).astype(np.float32)
    return map_x, map_y, valid


def yaw(image: np.ndarray, far_x: float | None, label: int, psi_deg: float,
        fov_deg: float = DEFAULT_FOV_DEG, out_of_frame: str = "unknown",
        ) -> tuple[np.ndarray, float | None, int, np.ndarray]:
    """Re-render an H×W(×C) frame as if the user had turned right by ``psi_deg`` degrees.

    Returns ``(image, far_x, label, valid)``: the warped frame (same shape and dtype, black
    where nothing was seen), the moved goal (None when unknown, off-frame or not measured),
    its bin 0..12, and an H×W bool mask of pixels that come from the original photo.
    """
    image = _check_image(image)
    new_x, new_label = yaw_label(far_x, label, psi_deg, fov_deg, out_of_frame)
    h, w = image.shape[:2]
    map_x, map_y, valid = _yaw_maps(w, h, float(psi_deg), fov_deg)
    warped = cv2.remap(np.ascontiguousarray(image), map_x, map_y, interpolation=cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    if warped.ndim < image.ndim:
        warped = warped[..., None]
    return warped, new_x, new_label, valid


def random_yaw(image: np.ndarray, far_x: float | None, label: int, rng: np.random.Generator,
               max_deg: float = 15.0, fov_deg: float = DEFAULT_FOV_DEG, out_of_frame: str = "unknown",
               ) -> tuple[np.ndarray, float | None, int, np.ndarray, float]:
    """:func:`yaw` by an angle drawn uniformly from ``[-max_deg, max_deg]``; returns it last."""
    psi = float(rng.uniform(-max_deg, max_deg))
    return (*yaw(image, far_x, label, psi, fov_deg, out_of_frame), psi)


def random_augment(image: np.ndarray, far_x: float | None, label: int, rng: np.random.Generator, *,
                   p_mirror: float = 0.5, max_yaw_deg: float = 0.0, fov_deg: float = DEFAULT_FOV_DEG,
                   out_of_frame: str = "unknown") -> tuple[np.ndarray, float | None, int, np.ndarray]:
    """On-the-fly augmentation for a training loop: mirror with probability ``p_mirror``, then
    (if ``max_yaw_deg`` > 0) yaw by an angle uniform in ``[-max_yaw_deg, max_yaw_deg]``.

    Returns ``(image, far_x, label, valid)`` like :func:`yaw` (``valid`` all True without yaw).
    """
    if rng.random() < p_mirror:
        image, far_x, label = mirror(image, far_x, label)
    if max_yaw_deg > 0:
        image, far_x, label, valid, _ = random_yaw(image, far_x, label, rng, max_yaw_deg, fov_deg, out_of_frame)
        return image, far_x, label, valid
    return image, far_x, parse_label(label), np.ones(np.asarray(image).shape[:2], dtype=bool)


# ----------------------------------------------------------------------------- field views

#: Aspects (width / height) of the frames a phone gives, with how often a field view uses each.
#: (Drawing mostly 1:1, what a portrait phone gives after a bundle's view crop, was cross-validated
#: on 2026-11-29 and did not help portrait frames: docs/models.md.)
FIELD_ASPECTS = ((3 / 4, 0.45), (9 / 16, 0.15), (1.0, 0.15), (16 / 9, 0.10), (4 / 3, 0.15))
#: Bump when :func:`field_view` draws differently with the same aspects: cached features of field
#: views are keyed by :func:`field_recipe`. 2 (2026-12-04): rolled corners filled with the pad
#: colour, as the runtime levels a frame (they were reflected, which could mirror the goal).
FIELD_VERSION = 2
#: The steps of a field view, in order; each (or one corruption by name) can be left out for an
#: ablation (``crossing-train --field-without``).
FIELD_STEPS = ("mirror", "roll", "aspect", "corruption")


def field_steps() -> tuple[str, ...]:
    """Every name :func:`field_view`'s ``without`` accepts: the steps, then each corruption."""
    from crossing_assist.data_tools.corrupt import CORRUPTIONS

    return FIELD_STEPS + tuple(CORRUPTIONS)


def field_recipe(without: tuple[str, ...] = (), zoom: float = 1.0) -> dict:
    """What :func:`field_view` draws from, as a cache key part: features of field views cached under
    another recipe are stale."""
    from crossing_assist.data_tools.corrupt import CORRUPTIONS

    recipe = {"aspects": [[round(a, 6), w] for a, w in FIELD_ASPECTS], "corruptions": sorted(CORRUPTIONS),
              "version": FIELD_VERSION}
    if without:   # keys of the full recipe unchanged
        recipe["without"] = sorted(without)
    if zoom > 1:
        recipe["zoom"] = round(float(zoom), 6)
    return recipe


def _goal(far_x: float | None, label: int) -> tuple[float | None, int]:
    """``(far_x, bin)`` with the label parsed; a voted bin without ``far_x`` stands at its centre."""
    label = parse_label(label)
    if far_x is None and label != UNKNOWN:
        far_x = bin_center_x(label)
    return far_x, label


def _in_window(far_x: float | None, label: int, x0: int, cw: int, w: int) -> tuple[float | None, int]:
    """The goal of a frame ``w`` px wide seen through its columns ``x0 .. x0 + cw``: its x in the
    window (:func:`window_x`: out of view, the edge strip) and bin; unknown stays unknown."""
    far_x, label = _goal(far_x, label)
    if far_x is None or label == UNKNOWN:
        return None, label
    x = window_x(far_x, x0 / w, cw / w)
    return x, x_to_bin(x)


def roll(image: np.ndarray, far_x: float | None, far_y: float, label: int, roll_deg: float,
         fill: str = "pad") -> tuple[np.ndarray, float | None, int]:
    """Rotate the frame by ``roll_deg`` about its centre (the phone tilted sideways; positive =
    counter-clockwise). The corners it uncovers: ``fill="pad"`` (training views) ``PAD_RGB``, as
    the runtime's levelling (:func:`crossing_assist.geometry.level`) fills them; ``"reflect"``
    the photo reflected in, standing for the scene a rolled camera would see there (scripts
    simulating one), which now and then shows a goal near a side edge twice. The goal at
    (far_x, far_y) rotates with it; a goal rotated out of the frame goes to the edge strip it
    left by (out of view, inferable)."""
    if fill not in ("pad", "reflect"):
        raise ValueError(f"Unknown fill: {fill!r}; valid: pad, reflect")
    image = _check_image(image)
    far_x, _ = _goal(far_x, label)
    h, w = image.shape[:2]
    m = cv2.getRotationMatrix2D((w / 2 - 0.5, h / 2 - 0.5), float(roll_deg), 1.0)
    border = ({"borderMode": cv2.BORDER_CONSTANT, "borderValue": tuple(int(v) for v in PAD_RGB)} if fill == "pad"
              else {"borderMode": cv2.BORDER_REFLECT_101})
    out = cv2.warpAffine(np.ascontiguousarray(image), m, (w, h), flags=cv2.INTER_LINEAR, **border)
    if far_x is None:
        return out, None, UNKNOWN
    px, py = far_x * w - 0.5, far_y * h - 0.5
    nx = m[0, 0] * px + m[0, 1] * py + m[0, 2]
    x = min(max((nx + 0.5) / w, 1e-6), 1 - 1e-6)
    return out, x, x_to_bin(x)


def crop_window(image: np.ndarray, far_x: float | None, label: int, aspect: float, offset: float,
                ) -> tuple[np.ndarray, float | None, int]:
    """A window of ``aspect`` (width / height) cut from the frame, as a phone of that aspect
    would see it: narrower aspects keep the full height and start at ``offset`` (0..1 of the
    free width); wider ones keep the full width and the rows around the middle. The goal moves
    exactly (``x' = (x - x0) / w'``); a goal outside the window lies in the edge strip."""
    image = _check_image(image)
    h, w = image.shape[:2]
    if aspect * h <= w:   # narrower than the frame: a vertical slice
        cw = max(1, int(round(aspect * h)))
        x0 = int(round(offset * (w - cw)))
        return (np.ascontiguousarray(image[:, x0:x0 + cw]), *_in_window(far_x, label, x0, cw, w))
    ch = max(1, int(round(w / aspect)))
    y0 = (h - ch) // 2
    return (np.ascontiguousarray(image[y0:y0 + ch]), *_goal(far_x, label))


def magnify(image: np.ndarray, far_x: float | None, label: int, scale: float, x_offset: float,
            y_offset: float = 0.5) -> tuple[np.ndarray, float | None, int]:
    """The frame seen ``scale`` (>= 1) times magnified: a window of the same aspect, ``1 / scale``
    of its width and height, at ``x_offset`` / ``y_offset`` (0..1) of the free width / height, as a
    narrower camera (or a portrait frame shown filling the canvas) would show it. The goal moves
    exactly; a goal outside the window lies in the edge strip (rows are not checked: the
    direction of a goal above or below the window is still its strip)."""
    image = _check_image(image)
    if not scale >= 1:
        raise ValueError(f"Invalid magnification {scale}; valid: >= 1")
    h, w = image.shape[:2]
    cw, ch = max(1, int(round(w / scale))), max(1, int(round(h / scale)))
    x0, y0 = int(round(x_offset * (w - cw))), int(round(y_offset * (h - ch)))
    return (np.ascontiguousarray(image[y0:y0 + ch, x0:x0 + cw]), *_in_window(far_x, label, x0, cw, w))


def field_view(image: np.ndarray, far_x: float | None, far_y: float, label: int,
               rng: np.random.Generator, without: tuple[str, ...] = (), zoom: float = 1.0,
               ) -> tuple[np.ndarray, float | None, int, str]:
    """One random view of a (true-aspect) photo as a user's phone might take it: mirrored
    (p 0.5), rolled by up to 15 degrees (p 0.7), cut to a phone aspect (:data:`FIELD_ASPECTS`,
    p 0.7), with ``zoom`` > 1 magnified by 1..``zoom`` (:func:`magnify`, p 0.5), and corrupted
    (:mod:`.corrupt`, p 0.7). Returns the view, its goal, bin and a tag.

    ``without`` names steps (:data:`FIELD_STEPS`) or corruptions left out, for an ablation: their
    random draws are still made, so every other step draws exactly what the full recipe does.
    ``zoom`` = 1 draws nothing for the magnification, so the recipe without it is unchanged."""
    from crossing_assist.data_tools.corrupt import CORRUPTIONS, corrupt

    tags = []
    if rng.random() < 0.5 and "mirror" not in without:
        image, far_x, label = mirror(image, far_x, label)
        tags.append("m")
    if rng.random() < 0.7:
        deg = float(rng.uniform(-15, 15))
        if "roll" not in without:
            image, far_x, label = roll(image, far_x, far_y, label, deg)
            tags.append(f"roll={deg:+.0f}")
    if rng.random() < 0.7:
        aspects, weights = zip(*FIELD_ASPECTS)
        aspect = float(aspects[rng.choice(len(aspects), p=np.asarray(weights) / sum(weights))])
        offset = float(rng.random())
        if "aspect" not in without:
            image, far_x, label = crop_window(image, far_x, label, aspect, offset)
            tags.append(f"aspect={aspect:.2f}")
    if zoom > 1 and rng.random() < 0.5:
        scale, x_off, y_off = float(rng.uniform(1.0, zoom)), float(rng.random()), float(rng.uniform(0.25, 0.75))
        image, far_x, label = magnify(image, far_x, label, scale, x_off, y_off)
        tags.append(f"zoom={scale:.2f}")
    if rng.random() < 0.7:
        name = str(rng.choice(list(CORRUPTIONS)))
        if "corruption" not in without and name not in without:
            image = corrupt(image, name, rng)
            tags.append(name)
    return image, far_x, parse_label(label), " ".join(tags)


def portrait_views(image: np.ndarray, far_x: float | None, label: int, n: int = 3, aspect: float = 3 / 4,
                   ) -> list[tuple[np.ndarray, float | None, int, bool]]:
    """``n`` windows of ``aspect`` (3:4 portrait by default) cut from a landscape photo at
    offsets spread evenly from its left to its right edge (:func:`crop_window`): (window, goal
    x in it or None when out of view, bin, goal in view). Out-of-view goals lie in the edge strip.
    A voted label without ``far_x`` stands at its strip's centre for the bin and for "in view"
    (as in :func:`crop_window`); its x stays None (no exact position to measure headings by)."""
    h, w = _check_image(image).shape[:2]
    cw = max(1, int(round(aspect * h)))
    goal, _ = _goal(far_x, label)
    out = []
    for k in range(n):
        off = k / (n - 1) if n > 1 else 0.5
        win, x, b = crop_window(image, far_x, label, aspect, off)
        x0 = int(round(off * (w - cw)))
        inside = goal is not None and b != UNKNOWN and 0.0 <= (goal * w - x0) / cw < 1.0
        out.append((win, x if inside and far_x is not None else None, b, inside))
    return out


def phone_views(image: np.ndarray, far_x: float | None, label: int, n: int = 3, *, fov_deg: float,
                train_fov_deg: float, aspect: float = 3 / 4) -> list[tuple[np.ndarray, float | None, int, bool]]:
    """What ``n`` phones of ``aspect`` (3:4 portrait by default) and horizontal FOV ``fov_deg``
    would see from where a landscape photo (``train_fov_deg`` across) was taken, at offsets spread
    from its left to its right edge: a window of the photo's width ``tan(fov/2) / tan(train/2)``,
    grown to ``aspect`` with its edge rows repeated above and below (rows the photo does not have,
    which a bundle's view crop (:func:`crossing_assist.geometry.view_rows`) removes again); or, for
    a wider aspect, its middle rows. Same tuples as :func:`portrait_views`."""
    h, w = _check_image(image).shape[:2]
    frac = math.tan(math.radians(fov_deg) / 2) / math.tan(math.radians(train_fov_deg) / 2)
    if not 0.0 < frac <= 1.0:
        raise ValueError(f"Invalid phone FOV {fov_deg} deg: wider than the photo's {train_fov_deg} deg")
    cw = max(1, int(round(frac * w)))
    fh = max(1, int(round(cw / aspect)))
    out = []
    for win, x, b, inside in portrait_views(image, far_x, label, n, aspect=cw / h):
        top = abs(fh - h) // 2
        if fh > h:
            win = cv2.copyMakeBorder(win, top, fh - h - top, 0, 0, cv2.BORDER_REPLICATE)
        else:
            win = np.ascontiguousarray(win[top:top + fh])
        out.append((win, x, b, inside))
    return out


#: The portrait views a photo is evaluated under (:func:`portrait_sets`).
PORTRAIT_SETS = ("portrait", "portrait_window")


def portrait_sets(image: np.ndarray, far_x: float | None, label: int, n: int, *, portrait_fov_deg: float,
                  train_fov_deg: float) -> dict[str, list[tuple[np.ndarray, float | None, int, bool, float]]]:
    """A landscape photo's portrait views, each with its camera's horizontal FOV:
    ``portrait``: what a phone held in portrait (3:4, ``portrait_fov_deg`` across) sees from the
    same spot (:func:`phone_views`); ``portrait_window``: 3:4 windows of the photo
    (:func:`portrait_views`), i.e. a narrower camera, whose FOV is the window's own."""
    w = _check_image(image).shape[1]
    windows = portrait_views(image, far_x, label, n)
    win_fov = window_fov(windows[0][0].shape[1] / w, train_fov_deg) if windows else train_fov_deg
    phone = phone_views(image, far_x, label, n, fov_deg=portrait_fov_deg, train_fov_deg=train_fov_deg)
    return {"portrait": [v + (portrait_fov_deg,) for v in phone],
            "portrait_window": [v + (win_fov,) for v in windows]}


def user_views(image: np.ndarray, far_x: float | None, label: int, n: int,
               geometry) -> dict[str, list[tuple[np.ndarray, float | None, int, bool, float | None]]]:
    """What a user's phone gives of one labelled photo, for a bundle of ``geometry`` (its
    ``camera_fov_deg`` and ``train_fov_deg``): ``landscape``, the photo as taken (FOV None = the
    bundle's), and with ``n`` > 0 views a photo the :func:`portrait_sets` at the bundle's portrait
    FOV; each view ``(frame, far_x, label, goal in view, FOV)``. Portrait views are cut from
    landscape photos only: they assume the photo spans the training camera's FOV across its width,
    and a portrait photo with a crossing already is what a phone held upright sees. A no-crossing
    frame already portrait (or square) is each set's view once, itself, at that set's FOV (its
    windows would be the frame again, counted ``n`` times at a landscape window's FOV)."""
    views = {"landscape": [(image, far_x, label, label != 0, None)]}
    if not n:
        return views
    phone_fov, train_fov = geometry.camera_fov_deg[1], geometry.train_fov_deg
    if image.shape[1] > image.shape[0]:
        views.update(portrait_sets(image, far_x, label, n, portrait_fov_deg=phone_fov, train_fov_deg=train_fov))
    elif label == UNKNOWN:   # a 3:4 window of a 4:3 photo spans 9/16 of its width
        views.update(portrait=[(image, None, UNKNOWN, False, phone_fov)],
                     portrait_window=[(image, None, UNKNOWN, False, window_fov(9 / 16, train_fov))])
    return views
