"""One camera held both ways: the same synthetic corners rendered in landscape (4:3) and in
portrait (3:4, the same camera turned), played through a bundle with and without its view crop.

The scene generator's geometry is exact, so this isolates what the fit does to a portrait frame:
whole frame letterboxed (shrunk to 3/4 of the training scale, sky and feet added) against the
schema-3 view crop (the middle rows at the training scale, crossing_assist/geometry.py). Each
frame is predicted once through the runtime's Engine (MC dropout, the bundle's samples); beacon on
= not unknown and the uncertainty under the bundle's gate threshold for the frame's orientation.
A diagnostic, not a benchmark of the product: synthetic corners, one frame each.

    .venv/bin/python scripts/portrait_synth.py [--bundle DIR] [--scenes 150]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys

import numpy as np

from crossing_assist.data_tools.synth import sample_view
from crossing_assist.data_tools.synth_scene import goal_label, render, sample_scene
from crossing_assist.runtime.engine import Engine

LANDSCAPE_FOV = 90.0                 # the synthetic training frames' camera (crossing-data synth)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bundle", default="crossing_assist/assets/default_bundle")
    ap.add_argument("--scenes", type=int, default=150)
    ap.add_argument("--seed", type=int, default=99)
    a = ap.parse_args(argv)
    crop = Engine(a.bundle, threads=2)
    whole = Engine(a.bundle, threads=2)
    whole.bundle = dataclasses.replace(whole.bundle, geometry=dataclasses.replace(whole.bundle.geometry, view_crop=False))
    # the same camera turned: its short side sees tan(fov/2) * 3/4
    portrait_fov = math.degrees(2 * math.atan(0.75 * math.tan(math.radians(LANDSCAPE_FOV) / 2)))
    rows: dict[str, list] = {"landscape": [], "portrait, whole frame": [], "portrait, view crop": []}
    for i in range(a.scenes):
        rng = np.random.default_rng([a.seed, i])
        scene = sample_scene(rng)
        cam = sample_view(scene, rng, LANDSCAPE_FOV, away=False)
        cam_p = dataclasses.replace(cam, fov_deg=portrait_fov)
        lab_l, lab_p = goal_label(scene, cam, 320, 240)[1], goal_label(scene, cam_p, 240, 320)[1]
        if lab_l == 0 or lab_p == 0:     # the goal in view both ways
            continue
        land = render(scene, cam, 320, 240, rng=np.random.default_rng(i))
        port = render(scene, cam_p, 240, 320, rng=np.random.default_rng(i))
        for name, eng, img, lab in (("landscape", crop, land, lab_l), ("portrait, whole frame", whole, port, lab_p),
                                    ("portrait, view crop", crop, port, lab_p)):
            p = eng.predict(img)          # the bundle's default FOV per orientation: the ratio of this camera's
            thr = eng.decision_config(p.orientation, p.fov_deg).threshold
            rows[name].append((p.action, lab, p.ok and p.action != 0 and p.uncertainty <= thr))
    print(f"{len(rows['landscape'])} synthetic corners with the goal in view both ways ({a.bundle})")
    print("| view | accuracy | bin MAE | beacon on | confidently wrong |\n|---|---|---|---|---|")
    for name, r in rows.items():
        act, lab, on = (np.asarray(c) for c in zip(*r))
        err = np.abs(act - lab)
        print(f"| {name} | {(err == 0).mean():.3f} | {err.mean():.2f} | {100 * on.mean():.1f} % | "
              f"{100 * ((err >= 2) & on).mean():.1f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
