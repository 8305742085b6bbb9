"""Procedural street corners seen from a pedestrian's phone, with the exact goal position.

Not photo-real, and honest about it: every frame made here is flagged ``synthetic``. What is
exact is the geometry: the scene is a ground plane with a road, kerbs, crossing markings, a
far facade and flat occluders (and, for zebra look-alikes, stairs or a crossing's picture on a
panel), ray-cast per pixel through a pinhole camera (horizontal field
of view ``fov_deg``, square pixels), so the goal (the far end of the crossing's midline, on
the far kerb) projects to a known ``far_x``.

World frame (metres): X right, Y up, Z forward when the user's heading is 0; the ground is
Y = 0. The crossing runs along the unit ground vector ``n`` (bearing ``theta``); the road
runs along ``u`` (perpendicular). A ground point ``p`` has across-road coordinate
``a = p·n`` (near kerb edge at ``a = near``, far kerb edge at ``a = near + road_width``) and
along-road coordinate ``b = p·u`` (crossing centred at ``b = offset``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from crossing_assist.actions import DEFAULT_FOV_DEG, UNKNOWN, x_to_bin

MARKINGS = ("zebra", "two_stripe", "faded", "none")
LIGHTINGS = ("day", "overcast", "dusk", "night", "sunny")


@dataclass(frozen=True)
class Occluder:
    """A flat upright rectangle parallel to the road at across-road ``a``, along-road [b0, b1]."""

    a: float
    b0: float
    b1: float
    height: float
    color: tuple[float, float, float]


@dataclass(frozen=True)
class Stairs:
    """A flight of ``steps`` steps (``rise`` × ``tread`` m, ``width`` wide) running along the
    crossing direction ``n`` from across-road ``start``, centred at along-road ``centre``, then a
    ``landing`` to the wall; ``down`` descends from the ground. Seen from a few metres its
    edges are bright bars across the view, as a zebra's are: a look-alike labelled unknown."""

    start: float
    centre: float
    width: float
    steps: int
    rise: float
    tread: float
    landing: float
    down: bool
    color: tuple[float, float, float]
    nosing: tuple[float, float, float]   # the strip along each step's edge
    nosing_depth: float

    @property
    def end(self) -> float:
        """Across-road position of the wall behind the landing."""
        return self.start + self.steps * self.tread + self.landing


@dataclass(frozen=True)
class Poster:
    """A picture of a crossing on an upright panel facing the user at across-road ``a``
    (a poster, shop screen or billboard): ``scene`` seen by ``camera`` fills along-road
    [b0, b1] and heights [y0, y1], inside a ``bezel``-wide frame; ``stand`` adds a post to the
    ground. A look-alike: the crossing is not there."""

    a: float
    b0: float
    b1: float
    y0: float
    y1: float
    scene: Scene
    camera: Camera
    bezel: float
    frame_color: tuple[float, float, float]
    stand: bool


@dataclass(frozen=True)
class Scene:
    """A street corner. Lengths in metres, angles in degrees, colours RGB in 0..1."""

    theta: float              # bearing of the crossing direction n (0 = straight ahead)
    near: float               # distance from the user to the near road edge along n
    road_width: float
    kerb_width: float
    offset: float             # along-road position of the crossing's midline
    crossing_width: float
    marking: str
    sidewalk_depth: float     # far sidewalk between far kerb and facade
    facade_height: float
    back_depth: float         # the user's own building line, at across-road a = -back_depth
    lighting: str
    has_road: bool            # False: a blank wall ahead, no crossing anywhere
    asphalt: tuple[float, float, float]
    paving: tuple[float, float, float]
    facade: tuple[float, float, float]
    occluders: tuple[Occluder, ...]
    texture_seed: int
    stairs: Stairs | None = None   # zebra look-alikes (scenes without a road)
    poster: Poster | None = None

    @property
    def n(self) -> np.ndarray:
        t = math.radians(self.theta)
        return np.array([math.sin(t), 0.0, math.cos(t)])

    @property
    def u(self) -> np.ndarray:
        t = math.radians(self.theta)
        return np.array([math.cos(t), 0.0, -math.sin(t)])

    @property
    def far(self) -> float:
        return self.near + self.road_width

    def goal(self) -> np.ndarray | None:
        """World position (3,) of the far end of the crossing's midline; None without a road."""
        if not self.has_road:
            return None
        return self.far * self.n + self.offset * self.u


@dataclass(frozen=True)
class Camera:
    """A phone at chest height: position (X, Z) on the ground, heading (yaw, + = right), pitch
    (+ = down), roll (+ = clockwise), height above ground (m) and horizontal FOV (deg)."""

    x: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    pitch: float = 10.0
    roll: float = 0.0
    height: float = 1.4
    fov_deg: float = DEFAULT_FOV_DEG

    def rotation(self) -> np.ndarray:
        """3×3 matrix taking camera coordinates (x right, y down, z forward) to world (X, Y, Z)."""
        cy, sy = math.cos(math.radians(self.yaw)), math.sin(math.radians(self.yaw))
        cp, sp = math.cos(math.radians(self.pitch)), math.sin(math.radians(self.pitch))
        cr, sr = math.cos(math.radians(self.roll)), math.sin(math.radians(self.roll))
        flip = np.diag([1.0, -1.0, 1.0])                        # camera y down -> world Y up
        roll = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
        pitch = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])   # tilt forward axis down
        yaw = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        return yaw @ pitch @ flip @ roll

    def position(self) -> np.ndarray:
        return np.array([self.x, self.height, self.z])

    def focal(self, width: int) -> float:
        return (width / 2) / math.tan(math.radians(self.fov_deg) / 2)


def project(camera: Camera, point: np.ndarray, width: int, height: int) -> tuple[float, float] | None:
    """Image position (fractions of width, height) of a world point; None when behind the camera."""
    c = camera.rotation().T @ (np.asarray(point, float) - camera.position())
    if c[2] <= 1e-6:
        return None
    f = camera.focal(width)
    return (f * c[0] / c[2] + width / 2) / width, (f * c[1] / c[2] + height / 2) / height


# ---------------------------------------------------------------- sampling


def sample_scene(rng: np.random.Generator, *, p_no_road: float = 0.0) -> Scene:
    """A random street corner (roughly in front of the user: |theta| <= 25°)."""
    road = float(rng.uniform(6.0, 16.0))
    cw = float(rng.uniform(2.5, 5.0))
    lighting = str(rng.choice(LIGHTINGS))
    grey = float(rng.uniform(0.18, 0.38))
    asphalt = tuple(np.clip(grey + rng.normal(0, 0.02, 3), 0, 1))
    pav = float(rng.uniform(0.45, 0.7))
    paving = tuple(np.clip(pav * np.array([1.0, 0.97, 0.92]) + rng.normal(0, 0.03, 3), 0, 1))
    facade = tuple(0.55 * rng.uniform(0.25, 0.8, 3) + 0.45 * rng.uniform(0.3, 0.7))
    near = float(rng.uniform(0.3, 2.0))
    offset = float(rng.uniform(-2.0, 2.0))
    occluders = []
    for _ in range(int(rng.integers(0, 4))):
        if rng.random() < 0.6:   # a car on the road
            a = float(rng.uniform(near + 1.0, near + road - 2.0))
            b0 = float(rng.uniform(-12, 10))
            occluders.append(Occluder(a, b0, b0 + float(rng.uniform(3.8, 4.8)), float(rng.uniform(1.3, 1.8)),
                                      tuple(rng.uniform(0.05, 0.9, 3))))
        else:                    # a person near the far kerb
            a = float(rng.uniform(near + road - 0.5, near + road + 1.5))
            b0 = float(offset + rng.uniform(-4, 4))
            occluders.append(Occluder(a, b0, b0 + 0.55, float(rng.uniform(1.5, 1.9)),
                                      tuple(rng.uniform(0.05, 0.6, 3))))
    return Scene(
        theta=float(rng.uniform(-25, 25)), near=near, road_width=road, kerb_width=float(rng.uniform(0.15, 0.4)),
        offset=offset, crossing_width=cw, marking=str(rng.choice(MARKINGS, p=[0.45, 0.2, 0.2, 0.15])),
        sidewalk_depth=float(rng.uniform(2.0, 6.0)), facade_height=float(rng.uniform(6.0, 25.0)),
        back_depth=float(rng.uniform(2.5, 6.0)),
        lighting=lighting, has_road=bool(rng.random() >= p_no_road), asphalt=asphalt, paving=paving,
        facade=facade, occluders=tuple(occluders), texture_seed=int(rng.integers(0, 2**31 - 1)),
    )


# ---------------------------------------------------------------- rendering


def _hash_noise(i: np.ndarray, j: np.ndarray, seed: int) -> np.ndarray:
    """Deterministic per-cell noise in [0, 1) for integer cell coordinates."""
    h = (i.astype(np.int64) * 73856093) ^ (j.astype(np.int64) * 19349663) ^ (seed * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    return ((h ^ (h >> 16)) & 0xFFFF).astype(np.float64) / 65536.0


def _value_noise(x: np.ndarray, y: np.ndarray, seed: int, scale: float) -> np.ndarray:
    """Smooth value noise in [0, 1) at world coordinates (metres) with cell size ``scale``."""
    gx, gy = x / scale, y / scale
    i, j = np.floor(gx), np.floor(gy)
    fx, fy = gx - i, gy - j
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    n00, n10 = _hash_noise(i, j, seed), _hash_noise(i + 1, j, seed)
    n01, n11 = _hash_noise(i, j + 1, seed), _hash_noise(i + 1, j + 1, seed)
    return (n00 * (1 - fx) + n10 * fx) * (1 - fy) + (n01 * (1 - fx) + n11 * fx) * fy


def _marking_mask(scene: Scene, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Paint coverage (0..1) of the crossing markings at road coordinates (a, b)."""
    inside_road = (a >= scene.near) & (a < scene.far)
    lateral = np.abs(b - scene.offset)
    if scene.marking == "none" or not scene.has_road:
        return np.zeros_like(a)
    if scene.marking == "two_stripe":
        line = np.abs(lateral - scene.crossing_width / 2) < 0.12
        return (inside_road & line).astype(np.float64)
    bars = np.mod(a - scene.near - 0.3, 1.0) < 0.5                  # 0.5 m bars, 0.5 m gaps
    mask = (inside_road & bars & (lateral < scene.crossing_width / 2)).astype(np.float64)
    if scene.marking == "faded":
        wear = _value_noise(a, b, scene.texture_seed + 7, 0.35)
        mask *= np.clip((wear - 0.35) * 2.5, 0, 1) * 0.6
    return mask


def _ground_color(scene: Scene, px: np.ndarray, pz: np.ndarray) -> np.ndarray:
    """RGB (…×3, 0..1) of ground points at world (px, pz)."""
    a = px * scene.n[0] + pz * scene.n[2]
    b = px * scene.u[0] + pz * scene.u[2]
    tex = _value_noise(px, pz, scene.texture_seed, 0.25) - 0.5
    paving = np.array(scene.paving)
    joints = (np.mod(a, 0.6) < 0.03) | (np.mod(b, 0.6) < 0.03)
    col = paving * (1 + 0.15 * tex)[..., None] * np.where(joints, 0.8, 1.0)[..., None]
    if scene.has_road:
        road = (a >= scene.near) & (a < scene.far)
        kerb = ((a >= scene.near - scene.kerb_width) & (a < scene.near)) | \
               ((a >= scene.far) & (a < scene.far + scene.kerb_width))
        asphalt = np.array(scene.asphalt) * (1 + 0.35 * tex)[..., None]
        centre = (np.abs(a - (scene.near + scene.far) / 2) < 0.08) & (np.mod(b, 6.0) < 3.0)
        paint = np.maximum(_marking_mask(scene, a, b), centre.astype(np.float64) * road)
        asphalt = asphalt * (1 - paint[..., None]) + 0.88 * paint[..., None]
        col = np.where(road[..., None], asphalt, col)
        col = np.where(kerb[..., None], np.array([0.72, 0.72, 0.7]) * (1 + 0.1 * tex)[..., None], col)
    return col


def _facade_color(scene: Scene, b: np.ndarray, y: np.ndarray) -> np.ndarray:
    base = np.array(scene.facade)
    windows = (np.mod(b, 3.0) > 1.0) & (np.mod(b, 3.0) < 2.2) & (np.mod(y, 3.2) > 1.0) & (np.mod(y, 3.2) < 2.4)
    door = (y < 2.4) & (np.mod(b, 9.0) < 1.4)
    tex = _value_noise(b, y, scene.texture_seed + 3, 0.5) - 0.5
    col = base * (1 + 0.2 * tex)[..., None]
    col = np.where(windows[..., None], np.array([0.15, 0.2, 0.28]), col)
    return np.where(door[..., None], base * 0.4, col)


def _sky_color(scene: Scene, up: np.ndarray) -> np.ndarray:
    top = {"day": (0.45, 0.62, 0.9), "sunny": (0.35, 0.58, 0.95), "overcast": (0.78, 0.8, 0.83),
           "dusk": (0.55, 0.45, 0.6), "night": (0.05, 0.06, 0.12)}[scene.lighting]
    low = np.array([0.9, 0.88, 0.85]) if scene.lighting != "night" else np.array([0.15, 0.12, 0.1])
    t = np.clip(up * 3, 0, 1)[..., None]
    return low * (1 - t) + np.array(top) * t


def _light(scene: Scene, rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    gain = {"day": 1.0, "sunny": 1.15, "overcast": 0.9, "dusk": 0.65, "night": 0.3}[scene.lighting]
    tint = {"day": (1, 1, 1), "sunny": (1.05, 1.0, 0.92), "overcast": (0.97, 0.99, 1.03),
            "dusk": (1.12, 0.92, 0.8), "night": (0.9, 0.95, 1.2)}[scene.lighting]
    out = rgb * gain * np.array(tint) * float(rng.uniform(0.85, 1.15))
    return np.clip(out, 0, 1)


def _hit_rect(o: np.ndarray, r: np.ndarray, axis: int, value: float, lo: tuple, hi: tuple,
              nearest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays (origin ``o`` (3,), directions ``r`` (…×3), both in road coordinates (a, b, y)) against
    the rectangle where coordinate ``axis`` is ``value`` and the other two lie in [lo, hi]:
    ``(hit, t, point)``, a hit only nearer than ``nearest``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (value - o[axis]) / r[..., axis]
        p = o + t[..., None] * r
        hit = (t > 1e-6) & (t < nearest)
        for i in range(3):
            if i != axis:
                hit &= (p[..., i] >= lo[i]) & (p[..., i] <= hi[i])
    return hit, t, p


def _draw_lookalikes(scene: Scene, o: np.ndarray, r: np.ndarray, nearest: np.ndarray, rgb: np.ndarray,
                     dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Paint the scene's stairs and poster over ``rgb`` where they are nearer than ``nearest``."""
    def paint(hit, t, col):
        nonlocal rgb, dist, nearest
        rgb = np.where(hit[..., None], col, rgb)
        dist = np.where(hit, t, dist)
        nearest = np.where(hit, t, nearest)

    s = scene.stairs
    if s is not None:
        b0, b1 = s.centre - s.width / 2, s.centre + s.width / 2
        base = np.array(s.color)
        sign = -1.0 if s.down else 1.0
        for k in range(s.steps):
            a_k = s.start + k * s.tread
            a_next = a_k + s.tread if k < s.steps - 1 else s.end
            y = sign * (k + 1) * s.rise
            hit, t, p = _hit_rect(o, r, 2, y, (a_k, b0, 0), (a_next, b1, 0), nearest)
            tex = _value_noise(p[..., 0], p[..., 1], scene.texture_seed + 11, 0.3) - 0.5
            edge = (a_next - p[..., 0] if s.down else p[..., 0] - a_k) < s.nosing_depth
            col = np.where(edge[..., None], np.array(s.nosing), base) * (1 + 0.2 * tex)[..., None]
            paint(hit, t, col)
            if not s.down:   # a riser faces the user only going up
                hit, t, _ = _hit_rect(o, r, 0, a_k, (0, b0, k * s.rise), (0, b1, (k + 1) * s.rise), nearest)
                paint(hit, t, base * 0.62)
        lo, hi = (-s.steps * s.rise, 0.0) if s.down else (0.0, s.steps * s.rise)
        for b in (b0, b1):   # the flight's sides, stepped like the treads
            hit, t, p = _hit_rect(o, r, 1, b, (s.start, 0, lo), (s.end, 0, hi), nearest)
            step = np.clip(np.floor((p[..., 0] - s.start) / s.tread) + 1, 1, s.steps) * s.rise
            hit &= (p[..., 2] >= -step) if s.down else (p[..., 2] <= step)
            paint(hit, t, base * 0.8)
    q = scene.poster
    if q is not None:
        e = q.bezel
        hit, t, p = _hit_rect(o, r, 0, q.a, (0, q.b0 - e, q.y0 - e), (0, q.b1 + e, q.y1 + e), nearest)
        if q.stand:
            mid = (q.b0 + q.b1) / 2
            post, t2, _ = _hit_rect(o, r, 0, q.a, (0, mid - 0.12, 0), (0, mid + 0.12, q.y0), nearest)
            hit, t = hit | post, np.where(post, t2, t)
        paint(hit, t, np.array(q.frame_color))
        hit, t, p = _hit_rect(o, r, 0, q.a - 1e-3, (0, q.b0, q.y0), (0, q.b1, q.y1), nearest)
        tw, th = (160, 120) if q.b1 - q.b0 >= q.y1 - q.y0 else (120, 160)   # the picture's pixels
        picture = render(q.scene, q.camera, tw, th, rng=np.random.default_rng(q.scene.texture_seed),
                         supersample=1, noise=0.5).astype(np.float64) / 255
        u = np.clip((p[..., 1] - q.b0) / (q.b1 - q.b0), 0, 1 - 1e-9)
        v = np.clip((q.y1 - p[..., 2]) / (q.y1 - q.y0), 0, 1 - 1e-9)
        with np.errstate(invalid="ignore"):
            col = picture[np.nan_to_num(v * th).astype(int), np.nan_to_num(u * tw).astype(int)]
        paint(hit, t, col)
    return rgb, dist


def render(scene: Scene, camera: Camera, width: int, height: int, *, rng: np.random.Generator,
           supersample: int = 2, noise: float = 1.0) -> np.ndarray:
    """Ray-cast the scene: an H×W×3 uint8 RGB frame. ``rng`` drives only exposure, sensor noise
    and blur; ``noise`` scales the sensor noise (0 = none)."""
    sw, sh = width * supersample, height * supersample
    f = camera.focal(width) * supersample
    u, v = np.meshgrid(np.arange(sw) + 0.5, np.arange(sh) + 0.5)
    rays = np.stack([(u - sw / 2) / f, (v - sh / 2) / f, np.ones_like(u)], -1) @ camera.rotation().T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    origin = camera.position()
    dist = np.full(u.shape, np.inf)
    rgb = _sky_color(scene, rays[..., 1])
    # ground
    down = rays[..., 1] < -1e-6
    t_g = np.where(down, -origin[1] / np.where(down, rays[..., 1], -1), np.inf)
    # planes parallel to the road (facades, occluders): a(t) = a0 + t * (ray·n)
    n_dot = rays @ scene.n
    a0 = origin @ scene.n
    b_org, b_dir = origin @ scene.u, rays @ scene.u
    stairs = scene.stairs
    bottom = -stairs.steps * stairs.rise if stairs is not None and stairs.down else 0.0
    if bottom < 0:   # a stairwell is a hole in the ground
        with np.errstate(invalid="ignore"):
            hole = (a0 + t_g * n_dot >= stairs.start) & (np.abs(b_org + t_g * b_dir - stairs.centre) <= stairs.width / 2)
        t_g = np.where(hole, np.inf, t_g)
    planes = [("facade", -scene.back_depth, -1e9, 1e9, scene.facade_height, None)]
    if scene.has_road:
        planes.append(("facade", scene.far + scene.kerb_width + scene.sidewalk_depth, -1e9, 1e9,
                       scene.facade_height, None))
        planes += [("occ", o.a, o.b0, o.b1, o.height, o.color) for o in scene.occluders]
    else:
        planes.append(("facade", scene.near + 1.5, -1e9, 1e9, scene.facade_height, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        for kind, a_p, b0, b1, top, color in planes:
            t = np.where(np.abs(n_dot) > 1e-6, (a_p - a0) / np.where(np.abs(n_dot) > 1e-6, n_dot, 1.0), np.inf)
            y = origin[1] + t * rays[..., 1]
            b = b_org + t * b_dir
            hit = (t > 0) & (t < dist) & (y >= bottom) & (y <= top) & (b >= b0) & (b <= b1) & (t < t_g)
            if kind == "facade":
                col = _facade_color(scene, b, y)
            else:
                shade = 0.75 + 0.25 * (y / top)
                col = np.array(color) * shade[..., None]
                col = np.where((y < 0.7)[..., None] & (top < 2.0) & (b1 - b0 > 2), np.array([0.05] * 3), col)
            rgb = np.where(hit[..., None], col, rgb)
            dist = np.where(hit, t, dist)
    if stairs is not None or scene.poster is not None:
        o = np.array([a0, b_org, origin[1]])
        r = np.stack([n_dot, b_dir, rays[..., 1]], -1)
        rgb, dist = _draw_lookalikes(scene, o, r, np.minimum(dist, t_g), rgb, dist)
    ground = down & (t_g < dist)
    gx = origin[0] + t_g * rays[..., 0]
    gz = origin[2] + t_g * rays[..., 2]
    gcol = _ground_color(scene, np.where(ground, gx, 0), np.where(ground, gz, 0))
    haze = np.clip(t_g / 80.0, 0, 0.6)[..., None]
    gcol = gcol * (1 - haze) + _sky_color(scene, np.zeros_like(t_g)) * haze
    rgb = np.where(ground[..., None], gcol, rgb)
    rgb = _light(scene, rgb, rng)
    img = cv2.resize((rgb * 255).astype(np.float32), (width, height), interpolation=cv2.INTER_AREA)
    sigma = float(rng.uniform(0.0, 0.8))
    if sigma > 0.2:
        img = cv2.GaussianBlur(img, (0, 0), sigma)
    noise_level = noise * (4.0 if scene.lighting != "night" else 9.0)
    if noise_level > 0:
        img = img + rng.normal(0, noise_level, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def goal_label(scene: Scene, camera: Camera, width: int, height: int) -> tuple[float | None, int, bool]:
    """``(far_x, label, blocked)`` of the goal in this view.

    The label is the goal's strip when it projects inside the frame (both axes), else
    unknown with ``far_x`` None. ``blocked`` is True when an occluder hides the goal.
    """
    goal = scene.goal()
    if goal is None:
        return None, UNKNOWN, False
    pos = project(camera, goal, width, height)
    if pos is None or not (0.0 <= pos[0] <= 1.0 and 0.0 <= pos[1] <= 1.0):
        return None, UNKNOWN, False
    origin = camera.position()
    ray = goal - origin
    a0, nd = origin @ scene.n, ray @ scene.n
    blocked = False
    for o in scene.occluders:
        if nd > 1e-9:
            t = (o.a - a0) / nd
            if 0 < t < 1:
                y = origin[1] + t * ray[1]
                b = origin @ scene.u + t * (ray @ scene.u)
                blocked |= bool(0 <= y <= o.height and o.b0 <= b <= o.b1)
    return float(pos[0]), x_to_bin(pos[0]), blocked
