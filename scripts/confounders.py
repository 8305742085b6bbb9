"""Does the beacon speak for things that look like a zebra crossing but are not one?

A probe of one kind of failure: procedural renders of zebra look-alikes (stairs up and down,
parking bays, lane and stop-line markings along a road, striped kerbs, speed humps, rail and
tram tracks, striped paving and decking, fences, railing and pergola shadows, striped awnings,
escalators, a zebra on a poster or screen) and of true zebra crossings as controls, each frame
played through the runtime exactly as ``scripts/silence_photos.py`` plays a still (its ``play``:
a 1 s still clip at 10 fps through engine + filter + gate; the last decision is what the user
hears). The beacon should stay silent on every look-alike and speak, at the right strip, on the
controls.

What the frames are: flat-shaded planar rectangles (ground, steps, walls, posters, simple car
boxes) ray-cast per pixel through ``synth_scene.Camera`` (its rotation and focal conventions and
``project``, so a control's goal strip is exact), value-noise textures, sky, haze, exposure,
blur and sensor noise; a phone at chest height, pitched 0-30 deg down, rolled a little. The
perspective is exact; the look is not photo-real (no shadows but painted ones, no reflections,
no people, simple materials). Landscape frames are 640x480 at 67 deg across and portrait ones
480x640 at 53 deg (the default bundle's cameras; ``--scale`` shrinks both, for tests), each
frame played at its render's FOV. Odd frames are portrait, even ones landscape.

So the rates here say which kinds of stripes fool a bundle and roughly how often, on these
renders: a probe of the kind of failure, not an estimate of how often the beacon speaks in the
field (that depends on how often a user meets each look-alike, and on real textures).

NEVER train on these renders, nor on frames made with this code, for the model they evaluate:
they are a held-out probe, and a model fitted to them would pass it without being any safer.
Training negatives for stairs, posters and the like belong in the synthetic data generator
(``crossing_assist.data_tools``), written separately, with their own code and seeds.

Determinism: frame ``i`` of a type is rendered from the random stream ``[crc32(stream name), i,
--seed]`` and played by an engine opened for that type alone (MC-dropout seed ``--seed``), so a
frame's picture and its answer depend only on the bundle, its type, ``i`` and ``--seed``:
``--types`` and a smaller ``--per-type`` replay the same frames with the same answers. The order
of the random draws inside each scene is part of its definition; change it and the frames
change (re-measure then). Each type has ``--per-type`` frames, the controls twice as many.

    .venv/bin/python scripts/confounders.py crossing_assist/assets/default_bundle --out runs/confounders

writes ``results.jsonl`` (one line a frame), ``summary.md`` (the tables it prints) and, when a
look-alike made the beacon speak, ``speaking.png`` (a contact sheet of those frames) into
``--out``. A missing or unusable bundle, ``--per-type`` < 1 or an unknown type is one line and
exit 1.
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from crossing_assist.actions import x_to_bin
from crossing_assist.data_tools.synth_scene import Camera, _hash_noise, _value_noise, project
from crossing_assist.fileio import atomic_path
from crossing_assist.geometry import orientation
from crossing_assist.runtime.listen import Listener

sys.path.insert(0, str(Path(__file__).resolve().parent))
from silence_photos import open_engine, play  # noqa: E402

LANDSCAPE = (640, 480, 67.0)   # width, height, horizontal FOV (deg): the default bundle's cameras
PORTRAIT = (480, 640, 53.0)
Y = np.array([0.0, 1.0, 0.0])


# ------------------------------------------------------------------ small helpers

def uni(rng, a, b):
    return float(rng.uniform(a, b))


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def fwd(deg):
    """The horizontal unit vector at bearing ``deg`` (+ = right of straight ahead)."""
    t = math.radians(deg)
    return np.array([math.sin(t), 0.0, math.cos(t)])


def rgt(deg):
    """Its right-hand perpendicular."""
    t = math.radians(deg)
    return np.array([math.cos(t), 0.0, -math.sin(t)])


def nz(x, y, seed, scale):
    """Zero-mean value noise."""
    return _value_noise(x, y, seed, scale) - 0.5


def cell_rand(i, seed):
    """Per-cell noise in [0, 1) for integer cells ``i``."""
    return _hash_noise(np.asarray(i), np.asarray(seed), 0)


def fov_of(W, H):
    return PORTRAIT[2] if H > W else LANDSCAPE[2]


def camera(rng, W, H, yaw, x=0.0, z=0.0, base_y=0.0, pitch=(0, 30)):
    """A phone at chest height above ``base_y``, at the FOV of its frame's orientation."""
    return Camera(x=x, z=z, yaw=yaw, pitch=uni(rng, *pitch), roll=float(rng.normal(0, 2)),
                  height=base_y + uni(rng, 1.25, 1.5), fov_deg=fov_of(W, H))


def lighting(rng):
    return str(rng.choice(["day", "overcast", "sunny", "dusk"], p=[0.35, 0.3, 0.25, 0.1]))


# ------------------------------------------------------------------ the ray caster

class Caster:
    """One frame: rays through every (supersampled) pixel, rectangles drawn nearest-first by a
    depth test, then sky, haze, exposure, blur and noise (:meth:`finish`)."""

    def __init__(self, cam: Camera, W: int, H: int, ss: int = 2):
        self.W, self.H, self.ss = W, H, ss
        sw, sh = W * ss, H * ss
        f = cam.focal(W) * ss
        u, v = np.meshgrid(np.arange(sw) + 0.5, np.arange(sh) + 0.5)
        d = np.stack([(u - sw / 2) / f, (v - sh / 2) / f, np.ones_like(u)], -1).reshape(-1, 3) @ cam.rotation().T
        self.d = d / np.linalg.norm(d, axis=1, keepdims=True)
        self.o = cam.position()
        self.depth = np.full(len(self.d), np.inf)
        self.rgb = np.zeros((len(self.d), 3))

    def quad(self, p0, e1, e2, L1, L2, fn):
        """The rectangle p0 + a e1 + b e2 (a in [0, L1], b in [0, L2], e1 ⟂ e2); ``fn(a, b, P)``
        gives the (N, 3) colours at its hits, or (colours, keep mask) for see-through patterns."""
        p0 = np.asarray(p0, float)
        e1, e2 = unit(e1), unit(e2)
        n = np.cross(e1, e2)
        den = self.d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((p0 - self.o) @ n) / den
        idx = np.flatnonzero((np.abs(den) > 1e-9) & (t > 1e-3) & (t < self.depth))
        if not len(idx):
            return
        P = self.o + t[idx, None] * self.d[idx]
        q = P - p0
        a, b = q @ e1, q @ e2
        m = (a >= 0) & (a <= L1) & (b >= 0) & (b <= L2)
        idx, P, a, b = idx[m], P[m], a[m], b[m]
        if not len(idx):
            return
        out = fn(a, b, P)
        if isinstance(out, tuple):
            col, keep = out
            idx, col = idx[keep], col[keep]
        else:
            col = out
        self.rgb[idx] = col
        self.depth[idx] = t[idx]

    def ground(self, fn):
        self.quad([-500, 0.0, -500], [1, 0, 0], [0, 0, 1], 1000, 1000, fn)

    def wall(self, p0, along, length, height, fn):
        """An upright rectangle from ground point ``p0`` along the horizontal ``along``."""
        self.quad(p0, along, Y, length, height, fn)

    def box(self, c, heading, L, Wd, y0, y1, col):
        f, r = fwd(heading), rgt(heading)
        c = np.array([c[0], y0, c[2]])
        base = c - f * L / 2 - r * Wd / 2

        def flat(k):
            return lambda a, b, P: np.tile(np.asarray(col) * k, (len(a), 1))
        self.quad(base, f, Y, L, y1 - y0, flat(0.8))
        self.quad(base + r * Wd, f, Y, L, y1 - y0, flat(0.8))
        self.quad(base, r, Y, Wd, y1 - y0, flat(0.7))
        self.quad(base + f * L, r, Y, Wd, y1 - y0, flat(0.7))
        self.quad(base + Y * (y1 - y0), f, r, L, Wd, flat(1.0))

    def car(self, c, heading, rng):
        col = rng.uniform(0.05, 0.85, 3) if rng.random() < 0.7 else np.full(3, uni(rng, 0.05, 0.9))
        L = uni(rng, 3.9, 4.8)
        self.box(c, heading, L, 1.8, 0.25, 0.95, col)
        self.box(c, heading, L * 0.55, 1.6, 0.95, 1.45, np.array([0.12, 0.14, 0.18]))

    def finish(self, rng, light="day", indoor=False):
        """The H x W x 3 uint8 RGB frame: sky (with clouds by day), haze outdoors, light, blur, noise."""
        sky = self.depth == np.inf
        dy = self.d[:, 1]
        top = {"day": (0.45, 0.62, 0.9), "sunny": (0.33, 0.56, 0.95), "overcast": (0.78, 0.8, 0.83),
               "dusk": (0.55, 0.45, 0.6), "indoor": (0.8, 0.8, 0.78)}[light]
        low = np.array([0.9, 0.88, 0.85])
        tt = np.clip(dy * 3, 0, 1)[:, None]
        skycol = low * (1 - tt) + np.array(top) * tt
        if light in ("day", "sunny"):
            cl = np.clip(_value_noise(self.d[:, 0] / (dy + 0.08), self.d[:, 2] / (dy + 0.08), 5, 1.5) * 2 - 1.0, 0, 1)
            skycol = skycol * (1 - 0.7 * cl[:, None]) + 0.95 * 0.7 * cl[:, None]
        rgb = np.where(sky[:, None], skycol, self.rgb)
        if not indoor:
            haze = np.clip(np.where(sky, 0, self.depth) / 120.0, 0, 0.6)[:, None]
            rgb = rgb * (1 - haze) + low * haze
        gain = {"day": 1.0, "sunny": 1.12, "overcast": 0.9, "dusk": 0.65, "indoor": 0.95}[light]
        tint = {"day": (1, 1, 1), "sunny": (1.05, 1.0, 0.92), "overcast": (0.97, 0.99, 1.03),
                "dusk": (1.12, 0.92, 0.8), "indoor": (1.04, 1.0, 0.93)}[light]
        rgb = np.clip(rgb * gain * np.array(tint) * uni(rng, 0.85, 1.15), 0, 1)
        img = (rgb.reshape(self.H * self.ss, self.W * self.ss, 3) * 255).astype(np.float32)
        img = cv2.resize(img, (self.W, self.H), interpolation=cv2.INTER_AREA)
        s = uni(rng, 0.0, 0.8)
        if s > 0.2:
            img = cv2.GaussianBlur(img, (0, 0), s)
        img = img + rng.normal(0, 4.0, img.shape)
        return np.clip(img, 0, 255).astype(np.uint8)


# ------------------------------------------------------------------ materials

def asphalt(P, seed, g):
    x, z = P[:, 0], P[:, 2]
    t = 0.6 * nz(x, z, seed, 0.4) + 0.4 * nz(x, z, seed + 1, 0.06)
    return (g * (1 + 0.35 * t))[:, None] * np.array([1.0, 1.0, 1.03])


def paving(P, seed, base, slab=0.6, ang=0.0):
    x, z = P[:, 0], P[:, 2]
    ca, sa = math.cos(math.radians(ang)), math.sin(math.radians(ang))
    a, b = x * ca - z * sa, x * sa + z * ca
    t = nz(x, z, seed, 0.25)
    j = (np.mod(a, slab) < 0.02) | (np.mod(b, slab * 1.5) < 0.02)
    v = 1 + 0.1 * t + 0.08 * (cell_rand(np.floor(a / slab) * 7919 + np.floor(b / slab / 1.5), seed) - 0.5)
    return np.asarray(base) * (v * np.where(j, 0.8, 1.0))[:, None]


def grass(P, seed):
    t = nz(P[:, 0], P[:, 2], seed, 0.3) + 0.5 * nz(P[:, 0], P[:, 2], seed + 2, 0.05)
    return np.array([0.25, 0.42, 0.15]) * (1 + 0.4 * t)[:, None]


def paint(col, mask, colour, seed, P):
    """Worn paint of ``colour`` over ``col`` where ``mask``."""
    wear = np.clip(0.9 + 0.3 * nz(P[:, 0], P[:, 2], seed + 11, 0.3), 0, 1)
    m = (mask * wear)[:, None]
    return col * (1 - m) + np.asarray(colour) * m


def facade_fn(base, seed, shop=False, win=(3.0, 1.2, 3.2, 1.4)):
    """A facade's colour function: windows above 3.2 m, shop windows at street level if ``shop``."""
    base = np.asarray(base)

    def fn(a, b, P):
        t = nz(a, b, seed, 0.5)
        col = base * (1 + 0.2 * t)[:, None]
        wx, ww, wy, wh = win
        w = (np.mod(a, wx) > 0.5) & (np.mod(a, wx) < 0.5 + ww) & (np.mod(b, wy) > 1.0) & (np.mod(b, wy) < 1.0 + wh) & (b > 3.2)
        col = np.where(w[:, None], np.array([0.15, 0.19, 0.26]) * (1 + 0.3 * t)[:, None], col)
        if shop:
            g = (b > 0.3) & (b < 2.6) & (np.mod(a, 5.0) > 0.4) & (np.mod(a, 5.0) < 4.4)
            col = np.where(g[:, None], np.array([0.2, 0.24, 0.28]) * (1 + 0.5 * nz(a, b, seed + 3, 1.0))[:, None], col)
        return col
    return fn


def rand_facade(rng):
    return 0.55 * rng.uniform(0.25, 0.8, 3) + 0.45 * uni(rng, 0.3, 0.7)


def backdrop(r, rng, p0, along, length=600, height=None, shop=False):
    r.wall(p0, along, length, height or uni(rng, 6, 25), facade_fn(rand_facade(rng), int(rng.integers(1e6)), shop))


def stone_wall(rng, seed):
    # draws its shade each time a quad it colours is hit: part of the stairs' random stream
    return lambda a, b, P: np.array([0.55, 0.54, 0.5]) * uni(rng, 0.7, 1.2) * (1 + 0.1 * nz(a, b, seed + 4, 0.4))[:, None]


# ------------------------------------------------------------------ scenes
# Each scene is fn(rng, W, H) -> (H x W x 3 uint8 RGB frame, {"variant": ..., "label": strip or 0}).

def zebra(rng, W, H, ss=2):
    """A true zebra crossing ahead (the control); ``label`` is its goal's strip, ``goal_x`` the
    goal's position across the frame (the far end of the crossing's midline)."""
    theta = uni(rng, -20, 20)
    n, u = fwd(theta), rgt(theta)
    near, road, cw, off = uni(rng, 0.3, 2.0), uni(rng, 6, 14), uni(rng, 2.5, 5), uni(rng, -1.5, 1.5)
    kerb, side = uni(rng, 0.15, 0.35), uni(rng, 2, 6)
    far = near + road
    period = uni(rng, 0.8, 1.2)
    bar = period * uni(rng, 0.45, 0.55)
    g = uni(rng, 0.18, 0.38)
    pv = uni(rng, 0.45, 0.7) * np.array([1, 0.97, 0.92])
    seed = int(rng.integers(1e6))
    goal = far * n + off * u
    for _ in range(200):   # aim until the goal is in view
        cam = camera(rng, W, H, theta + uni(rng, -15, 15))
        pos = project(cam, goal, W, H)
        if pos and 0.04 <= pos[0] <= 0.96 and 0.02 <= pos[1] <= 0.98:
            break
    r = Caster(cam, W, H, ss)
    cars = []
    for _ in range(int(rng.integers(0, 3))):
        b = off + float(rng.choice([-1, 1])) * (cw / 2 + uni(rng, 2.5, 12))
        cars.append((uni(rng, near + 1.5, far - 1.5) * n + b * u, theta + 90))
    for c, h in cars:
        r.car(c, h, rng)
    backdrop(r, rng, (far + kerb + side) * n - 300 * u, u, shop=rng.random() < 0.5)

    def gfn(a_, b_, P):
        A, B = P @ n, P @ u
        col = paving(P, seed, pv, ang=theta)
        ac = asphalt(P, seed, g)
        bars = (np.mod(A - near - 0.3, period) < bar) & (np.abs(B - off) < cw / 2) & (A < far - 0.2)
        centre = (np.abs(A - (near + far) / 2) < 0.07) & (np.mod(B, 6) < 3) & (np.abs(B - off) > cw / 2 + 1)
        ac = paint(ac, (bars | centre).astype(float), (0.88, 0.88, 0.86), seed, P)
        col = np.where(((A >= near) & (A < far))[:, None], ac, col)
        kb = ((A >= near - kerb) & (A < near)) | ((A >= far) & (A < far + kerb))
        return np.where(kb[:, None], np.array([0.72, 0.72, 0.7]), col)
    r.ground(gfn)
    img = r.finish(rng, lighting(rng))
    pos = project(cam, goal, W, H)
    in_view = bool(pos and 0 <= pos[0] <= 1 and 0 <= pos[1] <= 1)
    return img, {"variant": "zebra", "goal_x": pos[0] if pos else None, "label": x_to_bin(pos[0]) if in_view else 0}


def flight(r, origin, f, l, width, nsteps, rise, going, up, tread_fn, riser_fn):
    """A flight of ``nsteps`` steps from ``origin`` (the foot of the first riser going up, the
    top edge going down) along the horizontal ``f``, ``width`` wide, centred across ``l``."""
    base = np.asarray(origin, float) - l * width / 2
    for k in range(nsteps):
        if up:
            y0 = k * rise
            r.quad(base + f * k * going + Y * y0, l, Y, width, rise, riser_fn(k))
            r.quad(base + f * k * going + Y * (y0 + rise), l, f, width, going, tread_fn(k))
        else:
            yt = -(k + 1) * rise
            r.quad(base + f * k * going + Y * yt, l, f, width, going, tread_fn(k))
            r.quad(base + f * k * going + Y * yt, l, Y, width, rise, riser_fn(k))


def stair_materials(rng, seed):
    """Stone treads and risers, with contrasting nosing strips on 65 %: (tread(k, going),
    riser(k, rise), nosing?)."""
    stone = np.array([0.62, 0.6, 0.57]) * uni(rng, 0.6, 1.25)
    nos = rng.random() < 0.65
    nos_col = np.array([[0.9, 0.78, 0.1], [0.92, 0.92, 0.9], [0.12, 0.12, 0.12]][int(rng.integers(3))])
    if nos and stone.mean() < 0.5 and nos_col.mean() < 0.2:
        nos_col = np.array([0.92, 0.92, 0.9])
    nw = uni(rng, 0.04, 0.07)

    def tread(k, going):
        def fn(a, b, P):
            col = stone * (1 + 0.12 * nz(P[:, 0], P[:, 2] + k, seed, 0.2))[:, None]
            if nos:   # a strip along the front edge (b small going up, b large going down: going < 0)
                m = (b < nw) if going > 0 else (b > abs(going) - nw)
                col = np.where(m[:, None], nos_col, col)
            return col
        return fn

    def riser(k, rise):
        def fn(a, b, P):
            col = stone * 0.82 * (1 + 0.1 * nz(P[:, 0], P[:, 1] + k, seed + 1, 0.2))[:, None]
            if nos:
                col = np.where((b > rise - 0.03)[:, None], nos_col, col)
            return col
        return fn
    return tread, riser, nos


def stairs(rng, W, H, down=False):
    """A flight of 6-18 steps ahead, seen from its foot (up) or its top (down)."""
    seed = int(rng.integers(1e6))
    beta = uni(rng, -20, 20)
    f, l = fwd(beta), rgt(beta)
    width = uni(rng, 1.5, 8)
    n = int(rng.integers(6, 19))
    rise, going = uni(rng, 0.14, 0.18), uni(rng, 0.28, 0.36)
    tread, riser, nos = stair_materials(rng, seed)
    pv = uni(rng, 0.45, 0.7) * np.array([1, 0.97, 0.92])
    d0 = uni(rng, 1.0, 5.0) if not down else uni(rng, 0.3, 2.0)
    yaw = beta + uni(rng, -15, 15)
    cam = camera(rng, W, H, yaw, base_y=n * rise if down else 0.0)
    r = Caster(cam, W, H)
    top = n * rise
    run = n * going
    origin = d0 * f + (Y * top if down else 0)
    flight(r, origin, f, l, width, n, rise, going, not down,
           lambda k: tread(k, -going if down else going), lambda k: riser(k, rise))
    walls = rng.random() < 0.6
    wall_fn = stone_wall(rng, seed)
    if walls:
        for s in (-1, 1):
            r.wall(d0 * f + s * l * (width / 2 + 0.01) - f * 0.3, f, run + 0.3, top + 0.9, wall_fn)
    if not down:   # the top landing and a building beyond it
        r.quad((d0 + run) * f - l * 40 + Y * top, l, f, 80, 60, lambda a, b, P: paving(P, seed, pv))
        backdrop(r, rng, (d0 + run + uni(rng, 2, 12)) * f - l * 300 + Y * top, l, shop=rng.random() < 0.5)
        if not walls:   # the stair block's sides
            for s in (-1, 1):
                r.wall(d0 * f + s * l * width / 2, f, run, top, wall_fn)
        r.ground(lambda a, b, P: paving(P, seed, pv, ang=beta))
    else:          # the upper landing (the user's) and the street below
        r.quad(-40 * f - l * 40 + Y * top, l, f, 80, 40 + d0, lambda a, b, P: paving(P, seed, pv, ang=beta))
        low = rng.random() < 0.5
        gs, gg = seed + 9, uni(rng, 0.2, 0.35)
        r.ground(lambda a, b, P: asphalt(P, gs, gg) if low else paving(P, gs, pv * 0.9, ang=beta))
        backdrop(r, rng, (d0 + run + uni(rng, 6, 25)) * f - l * 300, l, shop=rng.random() < 0.5)
    img = r.finish(rng, lighting(rng))
    return img, {"variant": ("down" if down else "up") + ("+nosing" if nos else ""), "label": 0}


def street_scene(rng, W, H, kind):
    """A street along bearing beta, the user on the right pavement, the road to the left:
    ``road_along`` (lane lines, and at a junction a stop line, give-way line or yellow box),
    ``striped_kerb``, ``hump`` (a painted speed hump) or ``tram`` (tracks in the road)."""
    seed = int(rng.integers(1e6))
    beta = uni(rng, -10, 10)
    f, c_ = fwd(beta), rgt(beta)
    cR = -uni(rng, 0.3, 2.0)
    lanes = int(rng.choice([2, 2, 3, 4]))
    lw = uni(rng, 3.0, 3.6)
    cL = cR - lanes * lw
    kerb = uni(rng, 0.15, 0.3)
    pvR, pvL = uni(rng, 2, 5), uni(rng, 2, 5)
    g = uni(rng, 0.18, 0.38)
    pv = uni(rng, 0.45, 0.7) * np.array([1, 0.97, 0.92])
    white, yellow = np.array([0.88, 0.88, 0.86]), np.array([0.9, 0.75, 0.15])
    vs = uni(rng, 5, 25)
    wx = uni(rng, 8, 14)
    junction = kind == "road_along" and rng.random() < 0.8
    dash, gap = uni(rng, 2, 6), uni(rng, 3, 9)
    stop_style = str(rng.choice(["stop", "giveway", "box"], p=[0.55, 0.25, 0.2])) if junction else None
    kerb_cols = [(np.array([0.08, 0.08, 0.08]), white), (np.array([0.75, 0.12, 0.1]), white),
                 (yellow, np.array([0.08, 0.08, 0.08])), (np.array([0.1, 0.25, 0.7]), white)]
    kc = kerb_cols[int(rng.integers(4))]
    kp = uni(rng, 0.5, 1.0)
    hv, hl = uni(rng, 4, 14), uni(rng, 2.5, 4.5)
    hump_style = str(rng.choice(["transverse_bars", "longitudinal", "diagonal", "triangles"]))
    hump_col = [white, yellow][int(rng.integers(2))]
    hp = uni(rng, 0.5, 1.0)
    variant = {"road_along": f"lanes+{stop_style or 'no junction'}", "hump": hump_style}.get(kind, kind)
    if kind == "tram":
        tracks = [cL + lw * 0.5 + uni(rng, -0.3, 0.3), cL + lw * 1.5] if lanes >= 2 else [cL + lw / 2]

    def gfn(a_, b_, P):
        v, c = P @ f, P @ c_
        col = paving(P, seed, pv, ang=beta)
        road = (c >= cL) & (c < cR)
        xing = junction & (v > vs) & (v < vs + wx)
        ac = asphalt(P, seed, g)
        m = np.zeros(len(v))
        if kind != "tram":
            for k in range(1, lanes):
                cc = cL + k * lw
                if k == lanes // 2 and lanes == 2:
                    m = np.maximum(m, (np.abs(c - cc) < 0.06) & (np.mod(v, dash + gap) < dash))
                else:
                    m = np.maximum(m, (np.abs(c - cc) < 0.06) & (np.mod(v, dash + gap) < min(dash, 3)))
            m = np.maximum(m, (np.abs(c - (cR - 0.25)) < 0.06) | (np.abs(c - (cL + 0.25)) < 0.06))
        if junction:
            m = m * ~xing
            right_half = (c > cL + lanes * lw / 2) & (c < cR)
            if stop_style == "stop":
                m = np.maximum(m, right_half & (v > vs - 0.45) & (v < vs))
            elif stop_style == "giveway":
                m = np.maximum(m, right_half & (((v > vs - 0.25) & (v < vs)) | ((v > vs - 0.75) & (v < vs - 0.5)))
                               & (np.mod(c, 0.9) < 0.6))
            else:
                m = np.maximum(m, right_half & (v > vs - 0.3) & (v < vs))
                box = (v > vs) & (v < vs + wx) & road
                hatch = (np.abs(np.mod(v + c, 2.0) - 1.0) < 0.08) | (np.abs(np.mod(v - c, 2.0) - 1.0) < 0.08)
                edge = box & ((v < vs + 0.15) | (v > vs + wx - 0.15) | (c < cL + 0.15) | (c > cR - 0.15))
                ac = paint(ac, (box & hatch) | edge, yellow, seed, P)
        ac = paint(ac, m.astype(float), white, seed, P)
        if kind == "hump":
            hm = (v > hv) & (v < hv + hl) & road
            if hump_style == "transverse_bars":
                pm = hm & (np.mod(v - hv, hp) < hp / 2)
                ac = paint(ac, pm.astype(float), hump_col, seed, P)
            elif hump_style == "longitudinal":
                ac = np.where(hm[:, None], np.where((np.mod(c, hp) < hp / 2)[:, None], yellow, np.array([0.08] * 3)), ac)
            elif hump_style == "diagonal":
                ac = np.where(hm[:, None], np.where((np.mod(c + v, hp) < hp / 2)[:, None], yellow, np.array([0.08] * 3)), ac)
            else:
                tri = np.zeros(len(v), bool)
                for k in range(lanes):
                    cc = cL + (k + 0.5) * lw
                    tri |= (v > hv) & (v < hv + hl * 0.6) & (np.abs(c - cc) < 0.8 * (1 - (v - hv) / (hl * 0.6)))
                ac = paint(ac, tri.astype(float), white, seed, P)
                ac = np.where((hm & ~tri)[:, None], ac * np.array([1.5, 0.7, 0.6]), ac)   # a red-surfaced hump
        if kind == "tram":
            for tc in tracks:
                for s in (-0.7175, 0.7175):
                    groove = np.abs(c - (tc + s)) < 0.02
                    steel = (np.abs(c - (tc + s + 0.045)) < 0.025)
                    ac = np.where(groove[:, None], np.array([0.05] * 3), np.where(steel[:, None], np.array([0.6, 0.6, 0.62]), ac))
        col = np.where((road | (xing & (c > cL - pvL) & (c < cR + pvR)))[:, None], ac, col)
        kb = (((c >= cR) & (c < cR + kerb)) | ((c < cL) & (c >= cL - kerb))) & ~xing
        if kind == "striped_kerb":
            kcol = np.where((np.mod(v, 2 * kp) < kp)[:, None], kc[0], kc[1])
        else:
            kcol = np.array([0.72, 0.72, 0.7])
        return np.where(kb[:, None], kcol, col)

    # every entry draws (the kinds share one stream)
    yaw = beta + {"road_along": uni(rng, -25, 10), "striped_kerb": uni(rng, -60, 10),
                  "hump": uni(rng, -25, 10) if rng.random() < 0.75 else uni(rng, -60, -30),
                  "tram": uni(rng, -25, 10) if rng.random() < 0.6 else uni(rng, -90, -40)}[kind]
    cam = camera(rng, W, H, yaw)
    r = Caster(cam, W, H)
    for _ in range(int(rng.integers(0, 4))):   # parked cars, none at the junction
        v0 = uni(rng, 6, 60)
        if junction and vs - 3 < v0 < vs + wx + 3:
            continue
        side = rng.random() < 0.5
        r.car(v0 * f + (cL + 1.1 if side else cR - 1.1) * c_, beta, rng)
    if kind == "hump":   # the hump itself, 7 cm high with ramps, painted by the ground's function
        hh = 0.07
        ramp = min(1.0, hl / 3)
        p = hv * f + cL * c_
        e_up = unit(f * ramp + Y * hh)
        r.quad(p, c_, e_up, cR - cL, np.hypot(ramp, hh), gfn)
        r.quad(p + f * ramp + Y * hh, c_, f, cR - cL, hl - 2 * ramp, gfn)
        e_dn = unit(f * ramp - Y * hh)
        r.quad(p + f * (hl - ramp) + Y * hh, c_, e_dn, cR - cL, np.hypot(ramp, hh), gfn)
    for cc in (max(cR + pvR, 1.0), cL - pvL):
        fb = facade_fn(rand_facade(rng), int(rng.integers(1e6)), rng.random() < 0.5)
        hgt = uni(rng, 8, 25)
        if junction:
            r.wall(cc * c_ - 5 * f, f, vs + 5 - 1, hgt, fb)
            r.wall(cc * c_ + (vs + wx + 1) * f, f, 300, hgt, fb)
        else:
            r.wall(cc * c_ - 5 * f, f, 300, hgt, fb)
    if junction:   # buildings down the cross street, seen through the gap
        backdrop(r, rng, (vs - 10) * f + (max(cR + pvR, 1.0) + uni(rng, 15, 60)) * c_, f, wx + 20)
        backdrop(r, rng, (vs - 10) * f + (cL - pvL - uni(rng, 15, 60)) * c_, f, wx + 20)
    backdrop(r, rng, 250 * f + 300 * c_, -c_, 600)
    r.ground(gfn)
    img = r.finish(rng, lighting(rng))
    return img, {"variant": variant, "label": 0}


def parking(rng, W, H):
    """Two rows of parking bays (some hatched), the user standing in the aisle between them."""
    seed = int(rng.integers(1e6))
    th = uni(rng, -180, 180)
    n, u = fwd(th), rgt(th)
    bw, L = uni(rng, 2.3, 2.8), uni(rng, 4.8, 5.5)
    aisle = uni(rng, 5.5, 7)
    a0 = uni(rng, -8, -1)
    lw = uni(rng, 0.1, 0.15)
    g = uni(rng, 0.2, 0.4)
    col_line = np.array([0.88, 0.88, 0.86]) if rng.random() < 0.8 else np.array([0.9, 0.75, 0.15])
    hatch = rng.random() < 0.4
    hb = int(rng.integers(-3, 4))
    rows = [a0, a0 + L + aisle]

    def gfn(a_, b_, P):
        A, B = P @ n, P @ u
        ac = asphalt(P, seed, g)
        m = np.zeros(len(A), bool)
        for r0 in rows:
            inrow = (A > r0) & (A < r0 + L)
            across = np.mod(B + lw / 2, bw)
            m |= inrow & (np.abs(across - lw / 2) < lw / 2) & (across < lw)
            back = r0 if r0 == rows[0] else r0 + L
            m |= (np.abs(A - back) < lw / 2) & (np.abs(B) < 60)
            if hatch:
                m |= inrow & (B > hb * bw + lw) & (B < (hb + 1) * bw) & (np.mod(A + B, 0.8) < 0.15)
        return paint(ac, m.astype(float), col_line, seed, P)
    am = (a0 + L + aisle / 2) * n   # the middle of the aisle
    cam = camera(rng, W, H, uni(rng, -180, 180), x=float(am[0]), z=float(am[2]))
    r = Caster(cam, W, H)
    for r0 in rows:
        for k in range(-8, 8):
            if rng.random() < 0.3 and not (hatch and k == hb):
                r.car((r0 + L / 2) * n + (k + 0.5) * bw * u, th, rng)
    backdrop(r, rng, (a0 + 2 * L + aisle + uni(rng, 5, 30)) * n - 300 * u, u, shop=True)
    backdrop(r, rng, (a0 - uni(rng, 5, 30)) * n + 300 * u, -u, shop=True)
    r.ground(gfn)
    img = r.finish(rng, lighting(rng))
    return img, {"variant": "bays" + ("+hatched" if hatch else ""), "label": 0}


def rail(rng, W, H):
    """Railway track beside the user, or seen from a platform edge, or tram tracks in a street."""
    seed = int(rng.integers(1e6))
    var = str(rng.choice(["track", "platform", "tram"], p=[0.4, 0.3, 0.3]))
    if var == "tram":
        return street_scene(rng, W, H, "tram")
    beta = uni(rng, -10, 10)
    f, c_ = fwd(beta), rgt(beta)
    wood = rng.random() < 0.4
    slp = np.array([0.4, 0.3, 0.2]) if wood else np.array([0.62, 0.61, 0.58])
    two = rng.random() < 0.4
    if var == "track":
        cT = -uni(rng, 2.0, 4.0)
        base_y = 0.0
    else:
        cP = -uni(rng, 1.0, 3.0)
        cT = cP - 1.6
        base_y = 1.0
    tracks = [cT] + ([cT - 4.3] if two else [])
    on_grass = rng.random() < 0.6

    def gfn(a_, b_, P):
        v, c = P @ f, P @ c_
        col = grass(P, seed) if on_grass else paving(P, seed, np.array([0.5, 0.48, 0.45]))
        for tc in tracks:
            bal = np.abs(c - tc) < 1.8
            bcol = np.array([0.45, 0.42, 0.38]) * (1 + 0.5 * nz(P[:, 0], P[:, 2], seed, 0.04) + 0.2 * nz(P[:, 0], P[:, 2], seed + 1, 0.5))[:, None]
            sl = (np.abs(c - tc) < 1.3) & (np.mod(v, 0.6) < 0.25)
            bcol = np.where(sl[:, None], slp * (1 + 0.15 * nz(P[:, 0], P[:, 2], seed + 2, 0.1))[:, None], bcol)
            col = np.where(bal[:, None], bcol, col)
        return col
    cam = camera(rng, W, H, beta + uni(rng, -25, 10), base_y=base_y)
    r = Caster(cam, W, H)

    def steel(a, b, P):
        return np.tile(np.array([0.62, 0.62, 0.64]), (len(a), 1))

    def rust(a, b, P):
        return np.tile(np.array([0.3, 0.2, 0.13]), (len(a), 1))
    for tc in tracks:
        for s in (-0.7175, 0.7175):
            for e in (-0.035, 0.035):
                r.quad((tc + s + e) * c_ - 50 * f, f, Y, 400, 0.16, rust)
            r.quad((tc + s - 0.035) * c_ - 50 * f + Y * 0.16, c_, f, 0.07, 400, steel)
    if var == "platform":
        def pfn(a, b, P):
            c = P @ c_
            col = paving(P, seed, np.array([0.6, 0.58, 0.55]), ang=beta)
            col = np.where((np.abs(c - (cP + 0.55)) < 0.05)[:, None], np.array([0.92, 0.8, 0.1]), col)
            tact = (c > cP + 0.6) & (c < cP + 1.0)
            col = np.where(tact[:, None], np.array([0.75, 0.7, 0.5]) * (1 - 0.25 * (np.mod(P @ f, 0.067) < 0.02))[:, None], col)
            return np.where((c < cP + 0.1)[:, None], np.array([0.8, 0.8, 0.78]), col)
        r.quad(cP * c_ - 50 * f + Y * 1.0, c_, f, 30, 400, pfn)
        r.wall(cP * c_ - 50 * f, f, 400, 1.0, lambda a, b, P: np.array([0.5, 0.49, 0.46]) * (1 + 0.1 * nz(a, b, seed, 0.3))[:, None])
        backdrop(r, rng, (cP + uni(rng, 4, 8)) * c_ - 50 * f, f, 400, uni(rng, 4, 8))
    backdrop(r, rng, (min(tracks) - uni(rng, 5, 30)) * c_ + 300 * f, -f, 600)
    r.ground(gfn)
    img = r.finish(rng, lighting(rng))
    return img, {"variant": var + ("+wood" if wood else "+concrete") + ("+2 tracks" if two else ""), "label": 0}


def paving_stripes(rng, W, H):
    """Striped ground: decking (a boardwalk band or a terrace), striped tiles, or a tactile
    warning strip across plain paving."""
    seed = int(rng.integers(1e6))
    var = str(rng.choice(["decking", "striped_tiles", "tactile"], p=[0.4, 0.4, 0.2]))
    yaw = uni(rng, -180, 180)
    phi = yaw + (uni(rng, -20, 20) if rng.random() < 0.6 else uni(rng, 0, 180))   # the stripes' normal
    nrm = fwd(phi)
    band = rng.random() < 0.5
    bw = uni(rng, 2, 5)
    pw, gapw = uni(rng, 0.09, 0.2), uni(rng, 0.005, 0.012)
    wood = np.array([0.55, 0.38, 0.22]) * uni(rng, 0.7, 1.3)
    tw = uni(rng, 0.3, 0.9)
    light, dark = np.array([0.82, 0.8, 0.76]), np.array([0.25, 0.24, 0.23]) * uni(rng, 0.6, 1.4)
    td = uni(rng, 1, 6)
    pv = uni(rng, 0.45, 0.7) * np.array([1, 0.97, 0.92])
    side = fwd(phi + 90)
    grass_out = rng.random() < 0.5    # beside a boardwalk: grass, else water
    yellow_t = rng.random() < 0.5

    def gfn(a_, b_, P):
        s = P @ nrm
        t = P @ side
        if var == "decking":
            k = np.floor(s / pw)
            col = wood * (0.8 + 0.4 * cell_rand(k, seed))[:, None] * (1 + 0.15 * nz(s * 20, t, seed, 0.5))[:, None]
            col = np.where((np.mod(s, pw) < gapw)[:, None], wood * 0.25, col)
            out = grass(P, seed) if grass_out else np.array([0.2, 0.3, 0.35]) * (1 + 0.2 * nz(P[:, 0], P[:, 2], seed, 0.5))[:, None]
            if band:
                col = np.where((np.abs(t) < bw / 2)[:, None], col, out)
            return col
        if var == "striped_tiles":
            st = np.mod(s, 2 * tw) < tw
            col = np.where(st[:, None], light, dark) * (1 + 0.1 * nz(P[:, 0], P[:, 2], seed, 0.2))[:, None]
            j = (np.mod(s, tw) < 0.01) | (np.mod(t, 0.6) < 0.01)
            return col * np.where(j, 0.8, 1.0)[:, None]
        col = paving(P, seed, pv, ang=phi)
        d = P @ fwd(yaw)
        strip = (d > td) & (d < td + 0.8)
        tcol = np.array([0.85, 0.7, 0.2]) if yellow_t else pv * 1.1
        bars = np.mod(d, 0.067) < 0.03
        return np.where(strip[:, None], tcol * np.where(bars, 1.0, 0.7)[:, None], col)
    cam = camera(rng, W, H, yaw)
    r = Caster(cam, W, H)
    for _ in range(int(rng.integers(1, 4))):
        a = yaw + uni(rng, -60, 60)
        d = uni(rng, 10, 40)
        backdrop(r, rng, d * fwd(a) - 150 * rgt(a), rgt(a), 300, shop=rng.random() < 0.5)
    r.ground(gfn)
    img = r.finish(rng, lighting(rng))
    return img, {"variant": var + ("" if var != "decking" else ("+boardwalk" if band else "+terrace")), "label": 0}


def fence(rng, W, H):
    """A fence or railing across the view (pickets, horizontal slats or a railing), a facade,
    park or road behind it."""
    seed = int(rng.integers(1e6))
    var = str(rng.choice(["pickets", "horizontal_slats", "railing"]))
    yaw = uni(rng, -180, 180)
    along = rgt(yaw + uni(rng, -40, 40))
    D = uni(rng, 1.5, 6)
    col = [np.array([0.9, 0.9, 0.88]), np.array([0.08, 0.08, 0.08]), np.array([0.1, 0.3, 0.15]),
           np.array([0.5, 0.35, 0.2]), np.array([0.55, 0.57, 0.58])][int(rng.integers(5))]
    hgt = uni(rng, 1.0, 2.0) if var != "railing" else uni(rng, 0.9, 1.2)
    pitch_ = uni(rng, 0.1, 0.2)
    w = pitch_ * uni(rng, 0.25, 0.6) if var != "pickets" else pitch_ * uni(rng, 0.4, 0.7)
    slat = uni(rng, 0.08, 0.15)
    gapw = uni(rng, 0.015, 0.05)
    pv = uni(rng, 0.45, 0.7) * np.array([1, 0.97, 0.92])

    def ffn(a, b, P):
        if var == "horizontal_slats":
            keep = np.mod(b, slat + gapw) < slat
            keep |= np.mod(a, 2.0) < 0.08
        else:
            keep = np.mod(a, pitch_) < w
            keep |= (b > hgt - 0.06) | ((b > 0.1) & (b < 0.16)) | (np.mod(a, 2.5) < 0.06)
        c = col * (1 + 0.1 * nz(a, b, seed, 0.3))[:, None]
        return c, keep
    cam = camera(rng, W, H, yaw)
    r = Caster(cam, W, H)
    p0 = D * fwd(yaw) - 40 * along
    r.wall(p0, along, 80, hgt, ffn)
    nrm = np.cross(along, Y)
    nrm = nrm if nrm @ fwd(yaw) > 0 else -nrm
    behind = str(rng.choice(["park", "facade", "road"]))
    if behind == "facade":
        backdrop(r, rng, p0 + nrm * uni(rng, 3, 15), along, 80)
    else:
        def hedge(a, b, P):
            return np.array([0.15, 0.3, 0.12]) * (1 + 0.5 * nz(a, b, seed + 5, 0.3))[:, None]
        r.wall(p0 + nrm * uni(rng, 15, 40), along, 80, uni(rng, 3, 10), hedge)
    gs, gg = seed + 1, uni(rng, 0.2, 0.35)

    def gfn(a_, b_, P):
        front = (P - p0) @ nrm < 0
        back = grass(P, gs) if behind == "park" else asphalt(P, gs, gg)
        return np.where(front[:, None], paving(P, seed, pv), back)
    r.ground(gfn)
    img = r.finish(rng, lighting(rng))
    return img, {"variant": var + f"/{behind}", "label": 0}


def shadows(rng, W, H):
    """Striped sunlit shadows on plain paving: a railing's beside it, a pergola's overhead
    (the pergola itself out of view) or a long fence's, in sunshine."""
    seed = int(rng.integers(1e6))
    var = str(rng.choice(["railing", "pergola", "fence_long"]))
    beta = uni(rng, -180, 180)
    f, c_ = fwd(beta), rgt(beta)
    yaw = beta + uni(rng, -20, 20)
    pv = uni(rng, 0.55, 0.8) * np.array([1, 0.97, 0.92])
    cr = float(rng.choice([-1, 1])) * uni(rng, 0.8, 2.5)
    Ls = uni(rng, 0.6, 2.5)
    p = uni(rng, 0.1, 0.2) if var != "pergola" else uni(rng, 0.25, 0.6)
    duty = uni(rng, 0.3, 0.5)
    shear = math.tan(math.radians(uni(rng, -50, 50)))
    dark = uni(rng, 0.4, 0.6)
    ang = uni(rng, 20, 70) * float(rng.choice([-1, 1]))

    def gfn(a_, b_, P):
        v, c = P @ f, P @ c_
        col = paving(P, seed, pv, ang=beta)
        if var == "railing":
            region = (c * np.sign(cr) < abs(cr)) & (c * np.sign(cr) > abs(cr) - Ls)
            s = v + (abs(cr) - c * np.sign(cr)) * shear
            m = region & (np.mod(s, p) < p * duty)
            m |= np.abs(c * np.sign(cr) - (abs(cr) - Ls)) < 0.05
        elif var == "pergola":
            s = v + c * shear
            m = (np.mod(s, p) < p * duty) & (np.abs(c) < 4)
        else:
            s = v * math.cos(math.radians(ang)) + c * math.sin(math.radians(ang))
            m = np.mod(s, p) < p * duty
        return col * np.where(m, dark, 1.0)[:, None] * np.where(m[:, None], np.array([0.95, 0.98, 1.08]), 1.0)
    cam = camera(rng, W, H, yaw)
    r = Caster(cam, W, H)
    if var == "railing":
        bw = p * uni(rng, 0.2, 0.4)
        rcol = [np.array([0.1] * 3), np.array([0.85] * 3), np.array([0.5, 0.52, 0.55])][int(rng.integers(3))]
        r.wall(cr * c_ - 5 * f, f, 200, 1.1, lambda a, b, P: (np.tile(rcol, (len(a), 1)),
                                                              (np.mod(a, p) < bw) | (b > 1.04) | ((b > 0.08) & (b < 0.12))))
    for s in (-1, 1):
        backdrop(r, rng, s * uni(rng, 4, 15) * c_ - 5 * f, f, 300, shop=rng.random() < 0.5)
    backdrop(r, rng, uni(rng, 20, 60) * f + 300 * c_, -c_, 600)
    r.ground(gfn)
    img = r.finish(rng, "sunny")
    return img, {"variant": var, "label": 0}


def awning(rng, W, H):
    """A row of shops with striped awnings, across the street or close by along the facade."""
    seed = int(rng.integers(1e6))
    near = rng.random() < 0.35
    beta = uni(rng, -20, 20)      # the facade faces the camera, running along rgt(beta)
    f, c_ = fwd(beta), rgt(beta)
    D = uni(rng, 7, 20) if not near else uni(rng, 2, 4)
    pv = uni(rng, 0.45, 0.7) * np.array([1, 0.97, 0.92])
    g = uni(rng, 0.2, 0.35)
    road0, road1 = (uni(rng, 0.5, 1.5), D - uni(rng, 2, 4)) if not near else (None, None)
    yaw = beta + (uni(rng, -30, 30) if not near else float(rng.choice([-1, 1])) * uni(rng, 40, 70))
    cam = camera(rng, W, H, yaw, pitch=(0, 15))
    r = Caster(cam, W, H)
    palettes = [(np.array([0.75, 0.1, 0.1]), np.array([0.92, 0.92, 0.9])),
                (np.array([0.1, 0.4, 0.2]), np.array([0.92, 0.92, 0.9])),
                (np.array([0.1, 0.2, 0.5]), np.array([0.92, 0.92, 0.9])),
                (np.array([0.15, 0.15, 0.15]), np.array([0.9, 0.88, 0.8])),
                (np.array([0.85, 0.55, 0.1]), np.array([0.92, 0.9, 0.85]))]
    x = -30.0
    while x < 30:
        sw = uni(rng, 4, 9)
        if rng.random() < 0.8:
            c1, c2 = palettes[int(rng.integers(5))]
            sw_ = uni(rng, 0.15, 0.35)
            top, proj, drop = uni(rng, 2.9, 3.3), uni(rng, 1.2, 2.0), uni(rng, 0.5, 0.9)
            p0 = D * f + (x + 0.2) * c_ + Y * top
            e2 = unit(-f * proj - Y * drop)

            def afn(a, b, P, c1=c1, c2=c2, sw_=sw_):
                return np.where((np.mod(a, 2 * sw_) < sw_)[:, None], c1, c2) * (0.9 + 0.1 * (b / 2))[:, None]

            def valance(a, b, P, c1=c1, c2=c2, sw_=sw_):
                return np.where((np.mod(a, 2 * sw_) < sw_)[:, None], c1, c2) * 0.85
            r.quad(p0, c_, e2, sw - 0.4, np.hypot(proj, drop), afn)
            r.quad(p0 - f * proj - Y * (drop + 0.28), c_, Y, sw - 0.4, 0.28, valance)
        x += sw
    backdrop(r, rng, D * f - 300 * c_, c_, 600, shop=True)

    def gfn(a_, b_, P):
        v = P @ f
        col = paving(P, seed, pv, ang=beta)
        if road0 is not None:
            col = np.where(((v > road0) & (v < road1))[:, None], asphalt(P, seed, g), col)
            kerbs = ((v > road0 - 0.2) & (v < road0)) | ((v > road1) & (v < road1 + 0.2))
            col = np.where(kerbs[:, None], np.array([0.72, 0.72, 0.7]), col)
        return col
    if road0 is not None:
        for _ in range(int(rng.integers(0, 3))):
            r.car(uni(rng, road0 + 1, road1 - 1) * f + uni(rng, -15, 15) * c_, beta + 90, rng)
    r.ground(gfn)
    img = r.finish(rng, lighting(rng))
    return img, {"variant": "near/along facade" if near else "across street", "label": 0}


def escalator(rng, W, H):
    """One or two escalators indoors (steps with yellow edges), seen from below or above."""
    seed = int(rng.integers(1e6))
    from_above = rng.random() < 0.5
    beta = uni(rng, -10, 10)
    f, l = fwd(beta), rgt(beta)
    Ht = uni(rng, 3.5, 5.5)
    going, rise = 0.4, 0.231
    n = int(round(Ht / rise))
    Ht = n * rise
    width = 1.0
    two = rng.random() < 0.5
    metal = np.array([0.42, 0.42, 0.44]) * uni(rng, 0.7, 1.3)
    ycol = np.array([0.95, 0.8, 0.1])
    if from_above:
        pos = -uni(rng, 0.8, 3.0) * f
        cam = camera(rng, W, H, beta + uni(rng, -12, 12), x=float(pos[0]), z=float(pos[2]), base_y=Ht)
    else:
        pos = -uni(rng, 1.0, 4.0) * f
        cam = camera(rng, W, H, beta + uni(rng, -12, 12), x=float(pos[0]), z=float(pos[2]))
    r = Caster(cam, W, H)

    def tread(k):
        def fn(a, b, P):
            col = metal * np.where(np.mod(a, 0.02) < 0.009, 0.7, 1.0)[:, None]
            edge = (b > going - 0.045) if from_above else (b < 0.045)
            edge |= (a < 0.04) | (a > width - 0.04)
            return np.where(edge[:, None], ycol, col)
        return fn

    def riser(k):
        return lambda a, b, P: metal * 0.7 * np.where(np.mod(a, 0.02) < 0.009, 0.7, 1.0)[:, None]

    def grey(level):
        return lambda a, b, P: np.tile(np.array([level] * 3), (len(a), 1))
    lanes = [0.0] + ([float(rng.choice([-1, 1])) * 1.6] if two else [])
    run = n * going
    for lc in lanes:
        start = 1.0 * f + lc * l + (Y * Ht if from_above else 0)
        flight(r, start, f, l, width, n, rise, going, not from_above, tread, riser)
        # the flat comb plate at the bottom end
        flat = 0.0 if not from_above else run + 1.0
        r.quad(flat * f + lc * l - l * width / 2, l, f, width, 1.0, tread(0))
        # balustrades and handrails along the incline
        inc = unit(f * going + Y * (rise if not from_above else -rise))
        up = unit(Y - (Y @ inc) * inc)
        L = np.hypot(run, Ht)
        for s in (-1, 1):
            b0 = start + s * l * (width / 2 + 0.06) - up * 0.05
            r.quad(b0, inc, up, L, 1.0, lambda a, b, P: np.array([0.62, 0.68, 0.7]) * (1 + 0.05 * nz(a, b, seed, 0.5))[:, None])
            r.quad(b0 + up * 1.0 - l * 0.05, inc, l, L, 0.1, grey(0.05))
        # the dark steel skirt under the incline, between the balustrades
        r.quad(start - l * (width / 2 + 0.16) - up * 0.6, inc, l, L, width + 0.32, grey(0.3))
    tiles = np.array([0.75, 0.73, 0.7]) * uni(rng, 0.7, 1.1)

    def floor(a, b, P):
        return paving(P, seed, tiles, slab=0.6, ang=beta) * 1.05
    if from_above:
        r.quad(-30 * f - 30 * l + Y * Ht, l, f, 60, 31.0, floor)
    else:
        r.quad((run + 1.0) * f - 30 * l + Y * Ht, l, f, 60, 30, floor)
    r.ground(floor)
    ceil = Ht + 3.2
    r.quad(-60 * f - 60 * l + Y * ceil, l, f, 120, 120, lambda a, b, P: np.array([0.85, 0.85, 0.82]) *
           np.where((np.mod(P @ f, 3) < 0.3) & (np.mod(P @ l, 2) < 1.2), 1.15, 0.8)[:, None])
    for s in (-1, 1):
        r.wall(s * 7 * l - 60 * f, f, 120, ceil, facade_fn(rand_facade(rng) * 1.1, seed + s, True, (4.0, 3.0, 4.5, 2.0)))
    r.wall((run + 15) * f + 60 * l, -l, 120, ceil, facade_fn(rand_facade(rng), seed + 3, True, (4.0, 3.0, 4.5, 2.0)))
    r.wall(-20 * f - 60 * l, l, 120, ceil, facade_fn(rand_facade(rng), seed + 4, True, (4.0, 3.0, 4.5, 2.0)))
    img = r.finish(rng, "indoor", indoor=True)
    return img, {"variant": ("from above" if from_above else "from below") + ("+pair" if two else ""), "label": 0}


def poster(rng, W, H):
    """A picture of a zebra crossing (rendered by :func:`zebra`) on a billboard, a bus-shelter
    advert or a shop's screen, seen from the pavement."""
    seed = int(rng.integers(1e6))
    var = str(rng.choice(["billboard", "shelter_ad", "shop_screen"]))
    tw, th = (300, 400) if var == "shelter_ad" else (400, 300)
    tex, _ = zebra(rng, tw, th, ss=1)
    tex = tex.astype(np.float64) / 255.0
    Wp = {"billboard": uni(rng, 3, 6), "shelter_ad": 1.2, "shop_screen": uni(rng, 0.9, 1.6)}[var]
    Hp = Wp * th / tw
    y0 = {"billboard": uni(rng, 1.5, 3.5), "shelter_ad": 0.3, "shop_screen": uni(rng, 0.8, 1.3)}[var]
    beta = uni(rng, -30, 30)
    f, c_ = fwd(beta), rgt(beta)
    D = {"billboard": uni(rng, 4, 15), "shelter_ad": uni(rng, 1.2, 5), "shop_screen": uni(rng, 1.0, 4)}[var]
    off = uni(rng, -0.3, 0.3) * Wp
    target = D * f + off * c_
    yaw = math.degrees(math.atan2(target[0], target[2])) + uni(rng, -10, 10)
    cam = camera(rng, W, H, yaw, pitch=(0, 15) if var != "billboard" else (0, 5))
    r = Caster(cam, W, H)
    p0 = D * f + (off - Wp / 2) * c_ + Y * y0
    gloss = uni(rng, 0.0, 0.15)

    def pfn(a, b, P):
        i = np.clip(((Hp - b) / Hp * th).astype(int), 0, th - 1)
        j = np.clip((a / Wp * tw).astype(int), 0, tw - 1)
        return tex[i, j] * (1 - gloss) + gloss * 0.9
    r.quad(p0 - f * 0.02, c_, Y, Wp, Hp, pfn)
    bez = 0.05 if var != "billboard" else 0.15
    r.quad(p0 - c_ * bez - Y * bez, c_, Y, Wp + 2 * bez, Hp + 2 * bez,
           lambda a, b, P: np.tile(np.array([0.08] * 3) if var != "billboard" else np.array([0.3] * 3), (len(a), 1)))
    if var == "shelter_ad":
        r.quad(p0 - c_ * 2.0 - Y * y0 + f * 0.05, c_, Y, 4.0, 2.3, lambda a, b, P: (np.tile(np.array([0.2] * 3), (len(a), 1)),
                                                                                     (a < 0.06) | (a > 3.94) | (b > 2.22)))
        backdrop(r, rng, (D + uni(rng, 3, 15)) * f - 300 * c_, c_, 600, shop=True)
    else:
        backdrop(r, rng, D * f - 300 * c_, c_, 600, shop=var == "shop_screen")
    pv = uni(rng, 0.45, 0.7) * np.array([1, 0.97, 0.92])
    r.ground(lambda a, b, P: paving(P, seed, pv, ang=beta))
    img = r.finish(rng, lighting(rng))
    return img, {"variant": var, "label": 0}


# ------------------------------------------------------------------ the probe

@dataclass(frozen=True)
class Kind:
    """A type of frame: ``render(rng, W, H)``; ``stream``: the name whose CRC-32 seeds its frames
    (the audit's names, so its frames are the audit's); ``control``: a true zebra."""

    render: Callable
    stream: str
    control: bool = False


CONTROL = "zebra"
TYPES: dict[str, Kind] = {
    CONTROL: Kind(zebra, "CONTROL: true zebra", control=True),
    "stairs_up": Kind(lambda rng, W, H: stairs(rng, W, H, down=False), "stairs_up"),
    "stairs_down": Kind(lambda rng, W, H: stairs(rng, W, H, down=True), "stairs_down"),
    "parking_bays": Kind(parking, "parking_bays"),
    "lane_markings": Kind(lambda rng, W, H: street_scene(rng, W, H, "road_along"), "road_along (lanes/stop lines)"),
    "striped_kerb": Kind(lambda rng, W, H: street_scene(rng, W, H, "striped_kerb"), "striped_kerb"),
    "speed_hump": Kind(lambda rng, W, H: street_scene(rng, W, H, "hump"), "speed_hump"),
    "rail": Kind(rail, "rail/tram tracks"),
    "striped_paving": Kind(paving_stripes, "striped paving/decking"),
    "fence": Kind(fence, "fence/railing"),
    "shadows": Kind(shadows, "railing/pergola shadows"),
    "awning": Kind(awning, "striped awnings"),
    "escalator": Kind(escalator, "escalator"),
    "poster": Kind(poster, "zebra on poster/screen"),
}


def frame_size(i: int, scale: float = 1.0) -> tuple[int, int, float]:
    """(width, height, FOV) of frame ``i``: even ones landscape, odd ones portrait."""
    W, H, fov = PORTRAIT if i % 2 else LANDSCAPE
    return round(W * scale), round(H * scale), fov


def render(kind: str, i: int, seed: int = 0, scale: float = 1.0) -> tuple[np.ndarray, dict]:
    """Frame ``i`` of ``kind`` and its facts (``variant``; ``label``: a control's goal strip, 0
    for a look-alike or a goal out of view; ``goal_x`` for a control)."""
    W, H, _ = frame_size(i, scale)
    rng = np.random.default_rng([zlib.crc32(TYPES[kind].stream.encode()), i, seed])
    return TYPES[kind].render(rng, W, H)


def probe(bundle: Path, kinds: list[str], per_type: int, seed: int = 0, scale: float = 1.0):
    """Render and play every frame; yields ``(record, frame)``, ``record`` the results.jsonl line.
    One engine a type (MC-dropout seed ``seed``), so a frame's answer does not depend on which
    other types ran."""
    for kind in kinds:
        lis = Listener(open_engine(bundle, threads=1, seed=seed))
        for i in range(2 * per_type if TYPES[kind].control else per_type):
            frame, facts = render(kind, i, seed, scale)
            H, W = frame.shape[:2]
            fov = frame_size(i, scale)[2]
            p = play(lis, frame, fov)
            clip = lis.clips[-1]
            ok = [q for q in clip if q.ok]
            rec = {"type": kind, "variant": facts["variant"], "i": i, "orientation": orientation(W, H),
                   "width": W, "height": H, "fov_deg": fov, "label": int(facts["label"]),
                   "goal_x": facts.get("goal_x"), "on": bool(p.heard.on), "strip": int(p.heard.strip),
                   "threshold": float(p.threshold), "uncertainty": float(p.last.uncertainty) if p.last.ok else None,
                   "action": int(p.last.action), "p_unknown": float(p.last.probs[0]) if p.last.ok else None,
                   "min_uncertainty": float(min(q.uncertainty for q in ok)) if ok else None,
                   "strip_frames": sum(q.action != 0 for q in ok), "frames": len(clip)}
            yield rec, frame


def _strips(recs: list[dict]) -> str:
    c = collections.Counter(r["strip"] for r in recs if r["on"])
    return ", ".join(f"{k}×{v}" if v > 1 else str(k) for k, v in sorted(c.items())) or "—"


def _num(x: float | None, fmt: str) -> str:
    return "—" if x is None else format(x, fmt)


def _pct(k: int, n: int) -> str:
    return f"{100 * k / n:.1f} %" if n else "—"


def _lp(recs: list[dict]) -> str:
    nl = sum(r["orientation"] == "landscape" for r in recs)
    return f"{len(recs)} ({nl}/{len(recs) - nl})"


def summary(records: list[dict], measure_name: str, header: str = "") -> str:
    """The markdown tables: look-alikes (beacon on, strips, the gate measure of the speaking frames
    against their threshold), all look-alikes pooled, the controls, and look-alikes by variant."""
    by: dict[str, list[dict]] = collections.OrderedDict()
    for r in records:
        by.setdefault(r["type"], []).append(r)
    m = measure_name.replace("_", " ")
    lines = [header] if header else []
    lines += ["Look-alikes (no crossing: the beacon should stay silent)", "",
              f"| type | n (L/P) | beacon on | on % | strips (when on) | {m} / threshold, speaking frames | median {m} |",
              "|---|---|---:|---:|---|---|---:|"]
    n_all = on_all = 0
    for t, rs in by.items():
        if TYPES[t].control:
            continue
        on = [r for r in rs if r["on"]]
        n_all, on_all = n_all + len(rs), on_all + len(on)
        fm = ", ".join(f"{_num(r['uncertainty'], '.3f')}/{r['threshold']:.4f}" for r in on) or "—"
        med = np.median([r["uncertainty"] for r in rs if r["uncertainty"] is not None] or [math.nan])
        lines.append(f"| {t} | {_lp(rs)} | {len(on)} | {_pct(len(on), len(rs))} | {_strips(rs)} | {fm} | {med:.3f} |")
    lines.append(f"| **all look-alikes** | {n_all} | {on_all} | {_pct(on_all, n_all)} | | | |")
    controls = [r for t, rs in by.items() if TYPES[t].control for r in rs]
    if controls:
        on = [r for r in controls if r["on"]]
        view = [r for r in controls if r["label"]]
        right = sum(r["strip"] == r["label"] for r in on)
        near = sum(r["label"] and abs(r["strip"] - r["label"]) <= 1 for r in on)
        lines += ["", "Controls (a true zebra, the goal in view: the beacon should speak, at the goal's strip)", "",
                  "| type | n (L/P) | goal in view | beacon on | on % | right strip (of on) | within one strip (of on) | strips (when on) |",
                  "|---|---|---:|---:|---:|---:|---:|---|",
                  f"| {CONTROL} | {_lp(controls)} | {len(view)} | {len(on)} | {_pct(len(on), len(controls))} | "
                  f"{right} ({_pct(right, len(on))}) | {near} ({_pct(near, len(on))}) | {_strips(controls)} |"]
    lines += ["", "Look-alikes by variant", "", "| type | variant | n | beacon on |", "|---|---|---:|---:|"]
    for t, rs in by.items():
        if TYPES[t].control:
            continue
        var: dict[str, list[dict]] = collections.OrderedDict()
        for r in rs:
            var.setdefault(r["variant"], []).append(r)
        lines += [f"| {t} | {v} | {len(vs)} | {sum(r['on'] for r in vs)} |" for v, vs in var.items()]
    return "\n".join(lines) + "\n"


def contact_sheet(tiles: list[tuple[np.ndarray, str, str]], cols: int = 6, side: int = 240) -> np.ndarray:
    """The frames (RGB) on a white grid, each at most ``side`` px, with two caption lines in red."""
    out = []
    for img, top, bottom in tiles:
        h, w = img.shape[:2]
        s = side / max(h, w)
        img = cv2.resize(img, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
        t = np.full((side + 28, side, 3), 255, np.uint8)
        t[:img.shape[0], :img.shape[1]] = img
        for k, text in enumerate((top, bottom)):
            cv2.putText(t, text, (2, side + 11 + 13 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (200, 0, 0), 1, cv2.LINE_AA)
        out.append(t)
    blank = np.full_like(out[0], 255)
    out += [blank] * (-len(out) % cols)
    return np.vstack([np.hstack(out[k:k + cols]) for k in range(0, len(out), cols)])


def parse_types(text: str | None) -> list[str]:
    """The types asked for, in TYPES order; an unknown one is one line (SystemExit)."""
    if text is None:
        return list(TYPES)
    asked = [t.strip() for t in text.split(",") if t.strip()]
    if bad := [t for t in asked if t not in TYPES]:
        raise SystemExit(f"error: unknown type(s) {', '.join(bad)}; valid: {', '.join(TYPES)}")
    if not asked:
        raise SystemExit(f"error: no type given; valid: {', '.join(TYPES)}")
    return [t for t in TYPES if t in asked]


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="Never train on these renders: they are a held-out probe.")
    ap.add_argument("bundle", type=Path, help="bundle folder")
    ap.add_argument("--out", type=Path, required=True, help="folder for results.jsonl, summary.md, speaking.png")
    ap.add_argument("--per-type", type=int, default=18, metavar="N",
                    help="frames of each look-alike type (the controls: 2N); default 18")
    ap.add_argument("--types", metavar="T,T", help=f"comma-separated types (default all): {', '.join(TYPES)}")
    ap.add_argument("--seed", type=int, default=0, help="render and MC-dropout seed (default 0)")
    ap.add_argument("--scale", type=float, default=1.0,
                    help="frame size as a fraction of 640x480 / 480x640 (FOVs kept; default 1, tests: 0.2)")
    a = ap.parse_args(argv)
    kinds = parse_types(a.types)
    if a.per_type < 1:
        raise SystemExit(f"error: --per-type must be at least 1, got {a.per_type}")
    if not (a.scale > 0 and min(frame_size(0, a.scale)[:2]) >= 32):
        raise SystemExit(f"error: --scale {a.scale:g} makes frames under 32 px a side; valid: at least 0.067")
    if a.seed < 0:
        raise SystemExit(f"error: --seed must be >= 0, got {a.seed}")
    measure_name = open_engine(a.bundle, threads=1, seed=a.seed).measure   # a bad bundle fails here
    a.out.mkdir(parents=True, exist_ok=True)
    total = sum(2 * a.per_type if TYPES[k].control else a.per_type for k in kinds)
    records, tiles = [], []
    with open(a.out / "results.jsonl", "w") as fh, tqdm(total=total, unit="frame", desc="confounders") as bar:
        for rec, frame in probe(a.bundle, kinds, a.per_type, a.seed, a.scale):
            fh.write(json.dumps(rec) + "\n")
            fh.flush()
            records.append(rec)
            if rec["on"] and not TYPES[rec["type"]].control:
                tiles.append((frame, f"{rec['type']} #{rec['i']} {rec['variant']}",
                              f"strip {rec['strip']}, {measure_name} {_num(rec['uncertainty'], '.3f')}/{rec['threshold']:.4f}"))
            bar.set_postfix_str(f"{rec['type']} {'ON' if rec['on'] else 'off'}")
            bar.update()
    sheet = a.out / "speaking.png"
    if tiles:
        with atomic_path(sheet) as tmp:
            cv2.imwrite(str(tmp), contact_sheet(tiles)[..., ::-1])
    else:
        sheet.unlink(missing_ok=True)
    header = (f"Confounder probe of `{a.bundle}`: {a.per_type} per look-alike type, {2 * a.per_type} controls, "
              f"seed {a.seed}, scale {a.scale:g}; each frame a 1 s still clip at 10 fps through the runtime, "
              f"the last decision heard. Look-alike frames that spoke: {'speaking.png' if tiles else 'none'}.\n")
    text = summary(records, measure_name, header)
    with atomic_path(a.out / "summary.md") as tmp:
        tmp.write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
