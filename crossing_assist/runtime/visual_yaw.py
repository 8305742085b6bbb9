"""The camera's turn between two frames, read from the frames themselves (no gyroscope).

A user looking for the crossing sweeps the phone; without a yaw input the decision logic's
belief and heading hold stay where the goal was while the view moves (``scripts/pan_probe.py``).
A turn about the vertical axis slides the whole picture sideways, so the turn between two
consecutive frames is the horizontal shift that best lines up their thumbnails:

1. each frame becomes a grey thumbnail :data:`THUMB_WIDTH` pixels wide (area mean; its height
   keeps the frame's aspect), less its mean (an exposure change is not a turn);
2. the middle of the new thumbnail (all but a quarter of its width at each side, and ``DY``
   rows) is compared with the old one shifted by every whole pixel ``dx`` up to a quarter of the
   width either way and ``dy`` up to ``DY`` (a step's bob): the mean absolute difference, each
   less its own mean; the best ``dx`` is refined to a fraction of a pixel by the V through its
   neighbours' scores (an absolute difference's shape near its minimum: a parabola there is off
   by a tenth of a pixel, a tenth of a slow turn);
3. the shift is trusted only when the scene has texture (sd >= :data:`MIN_TEXTURE` in the middle
   compared and in the old thumbnail), the best score is clearly a match (<= :data:`MAX_MATCH` of
   the median score of all shifts: two unrelated pictures score alike at every shift), the best
   ``dx`` is inside the range searched, **no other shift matches nearly as well** (another local
   minimum of the scores, each ``dx``'s best over ``dy``, 2 pixels or more away and within
   :data:`AMBIGUOUS` times the best: a repeating pattern, such as a zebra's stripes under a
   walker's feet, matches a period off as well as in place: on synthetic walks that read
   -130 to -200 deg/s for single frames, and the belief jumped two strips), and **no part of the
   picture moves otherwise**: the middle
   is cut into a :data:`TILES` x :data:`TILES` grid, and a tile with texture whose own best shift
   scores under 1 / :data:`TILE_VETO` of its best within a pixel of the chosen ``dx`` vetoes it
   (a camera's turn moves the whole picture; a bus or a person passing a still camera moves part
   of it, which without this read as a turn: a bus over half the view, 22 deg a pass). A blank
   wall, a passing bus, a person walking by, a frame swap or a brightness jump gives *no turn*
   (0), never a guess; a shift under :data:`MIN_SHIFT` is a still camera (a still scene's
   neighbours never score quite alike: left alone, that reads as a slow steady turn, ~1 deg/s at
   30 frames a second);
4. ``dx`` pixels are ``atan(dx / f)`` degrees, ``f`` the thumbnail's focal length in pixels
   for the camera's horizontal FOV; the picture moving left (content at ``x`` came from
   ``x + dx``, ``dx > 0``) is a turn to the right (+), the decision logic's sign.

The app has the same estimator (``android_demo/www/js/visualyaw.js``); ``shift_between`` of
both is pinned by the shared test vectors. numpy only (this is the runtime).
"""

from __future__ import annotations

import math

import numpy as np

THUMB_WIDTH = 64       # thumbnail width in pixels
DY = 2                 # vertical shifts searched either way (pixels of the thumbnail)
MIN_TEXTURE = 2.0      # thumbnail standard deviation (0..255 grey) below which a frame cannot show a turn
MAX_MATCH = 0.5        # the best shift must score at most this fraction of the median shift's score
MIN_SHIFT = 0.05       # a shift under this (thumbnail pixels) is a still camera (its picture's own asymmetry)
TILES = 3              # the middle is cut into TILES x TILES tiles, each able to veto a shift
TILE_VETO = 2.0        # ... when its score near the shift is over this many times its own best
AMBIGUOUS = 1.25       # another local minimum of the shifts' scores within this many times the best: cannot tell
MAX_TURN_DPS = 360.0   # a turn faster than this between two frames is not believed (a swap, a cut)


def thumbnail(frame_rgb: np.ndarray, width: int = THUMB_WIDTH) -> np.ndarray:
    """Grey (mean of R, G, B) area-mean thumbnail, ``width`` wide, its height from the frame's
    aspect (at least 8): cell ``(i, j)`` averages rows ``floor(i H / h) .. floor((i+1) H / h)`` and
    the columns alike, float64 0..255 (whole-number sums, one division: a port gets the same values)."""
    f = np.asarray(frame_rgb)
    if f.ndim != 3 or f.shape[2] < 3 or min(f.shape[:2]) < 2:
        raise ValueError(f"expected an H x W x 3 frame, got shape {f.shape}")
    h_in, w_in = f.shape[:2]
    w = min(width, w_in)
    h = min(h_in, max(8, int(round(w * h_in / w_in))))
    grey = f[..., 0].astype(np.int32)              # R + G + B: whole numbers, exact sums
    grey += f[..., 1]
    grey += f[..., 2]
    ys = (np.arange(h + 1) * h_in) // h            # strictly increasing: h <= h_in, w <= w_in
    xs = (np.arange(w + 1) * w_in) // w
    box = np.add.reduceat(np.add.reduceat(grey, ys[:-1], axis=0, dtype=np.int64), xs[:-1], axis=1)
    area = np.diff(ys)[:, None] * np.diff(xs)[None, :]
    return box / (3.0 * area)


def _middle(cur: np.ndarray) -> tuple[int, int, np.ndarray]:
    """``(M, DY', template)``: the middle of ``cur`` compared with the shifted old thumbnail, all but
    ``M = width // 4`` columns and ``DY' = min(DY, height // 4)`` rows at each side."""
    h, w = cur.shape
    m, dy = max(1, w // 4), min(DY, h // 4)
    return m, dy, cur[dy:h - dy, m:w - m]


def _tiles(th: int, tw: int) -> tuple[np.ndarray, np.ndarray]:
    """First row and first column of each of the middle's :data:`TILES` x :data:`TILES` tiles."""
    return (np.arange(TILES) * th) // TILES, (np.arange(TILES) * tw) // TILES


def tile_scores(prev: np.ndarray, cur: np.ndarray) -> np.ndarray:
    """Sums [dy + DY', dx + M, i, j] over tile (i, j) of the middle of ``cur`` of the absolute
    difference with the window of ``prev`` shifted by ``(dx, dy)``, each (the middle, the window)
    less its own mean."""
    _, _, tpl = _middle(cur)
    win = np.lib.stride_tricks.sliding_window_view(prev, tpl.shape)        # [2dy+1, 2m+1, th, tw]
    diff = win - win.mean(axis=(2, 3), keepdims=True)                      # one array, then in place
    diff -= tpl - tpl.mean()
    ry, rx = _tiles(*tpl.shape)
    return np.add.reduceat(np.add.reduceat(np.abs(diff, out=diff), ry, axis=2), rx, axis=3)


def shift_scores(prev: np.ndarray, cur: np.ndarray) -> np.ndarray:
    """Scores [dy + DY', dx + M] of every shift: the mean absolute difference between the middle
    of ``cur`` and the window of ``prev`` shifted by ``(dx, dy)``, each less its own mean."""
    tiles = tile_scores(prev, cur)
    return tiles.sum(axis=(2, 3)) / _middle(cur)[2].size


def shift_between(prev: np.ndarray, cur: np.ndarray) -> float | None:
    """Horizontal shift in thumbnail pixels such that ``cur[x] ~ prev[x + shift]`` (+: the picture
    moved left, the camera turned right; 0 under :data:`MIN_SHIFT`); None when the pair cannot
    tell (thumbnails of different sizes, too little texture in the middle of ``cur`` or in
    ``prev``, no shift clearly a match, the best at an end of the range searched, another shift
    matching nearly as well, a tile of the middle vetoing it)."""
    if prev.shape != cur.shape:
        return None
    _, _, tpl = _middle(cur)
    if float(tpl.std()) < MIN_TEXTURE or float(prev.std()) < MIN_TEXTURE:
        return None
    tiles = tile_scores(prev, cur)
    scores = tiles.sum(axis=(2, 3)) / tpl.size
    iy, ix = np.unravel_index(int(np.argmin(scores)), scores.shape)
    best = scores[iy, ix]
    if not best <= MAX_MATCH * float(np.median(scores)) or not 0 < ix < scores.shape[1] - 1:
        return None
    prof = scores.min(axis=0)                           # each dx's best over dy
    inner, k = prof[1:-1], np.arange(1, len(prof) - 1)
    if np.any((np.abs(k - ix) >= 2) & (inner < prof[:-2]) & (inner <= prof[2:]) & (inner <= AMBIGUOUS * best)):
        return None                                     # a repeating pattern: matched a period off as well
    ry, rx = _tiles(*tpl.shape)
    for i, rows in enumerate(np.split(tpl, ry[1:], axis=0)):
        for j, part in enumerate(np.split(rows, rx[1:], axis=1)):
            own = tiles[:, :, i, j]
            if float(part.std()) >= MIN_TEXTURE and not own[:, ix - 1:ix + 2].min() <= TILE_VETO * own.min():
                return None                             # this part of the picture moved otherwise
    a, c = scores[iy, ix - 1], scores[iy, ix + 1]      # the V through the best and its neighbours
    rise = max(a, c) - best
    shift = float(ix - scores.shape[1] // 2) + (0.5 * (a - c) / rise if rise > 0 else 0.0)
    return shift if abs(shift) >= MIN_SHIFT else 0.0


def shift_to_deg(shift_px: float, width_px: int, fov_deg: float) -> float:
    """A horizontal shift of ``shift_px`` in an image ``width_px`` wide seen by a camera ``fov_deg``
    across, as the camera's turn in degrees (+ = right)."""
    f = (width_px / 2) / math.tan(math.radians(fov_deg) / 2)
    return math.degrees(math.atan(shift_px / f))


class VisualYaw:
    """The camera's turn rate from consecutive frames: :meth:`update` with each frame gives the
    yaw rate (deg/s, + = right) since the previous one, 0 when it cannot tell."""

    def __init__(self, width: int = THUMB_WIDTH) -> None:
        self.width = width
        self.prev: np.ndarray | None = None
        self.t_prev: float | None = None

    def reset(self) -> None:
        self.prev = self.t_prev = None

    def update(self, frame_rgb: np.ndarray | None, t: float, fov_deg: float | None) -> float:
        """The yaw rate between the last frame and ``frame_rgb`` taken at ``t`` seconds, seen with
        a camera ``fov_deg`` across; a missing or unreadable frame or FOV starts afresh (0)."""
        try:
            thumb = None if frame_rgb is None or fov_deg is None else thumbnail(frame_rgb, self.width)
        except ValueError:
            thumb = None
        prev, t_prev = self.prev, self.t_prev
        self.prev, self.t_prev = thumb, (t if thumb is not None else None)
        if thumb is None or prev is None or t_prev is None or not t > t_prev:
            return 0.0
        shift = shift_between(prev, thumb)
        if shift is None:
            return 0.0
        rate = shift_to_deg(shift, thumb.shape[1], fov_deg) / (t - t_prev)
        return rate if abs(rate) <= MAX_TURN_DPS else 0.0
