"""Held-out check of the per-aspect default FOV (``geometry.sensor_aspect``): 9:16 portrait video
frames of the scenes of photographers each fold never trained on, through each fold's bundle,
read with the crop's FOV (~41 deg, what a 4:3 sensor's 9:16 crop sees across) against the
per-orientation constant (53 deg) that 9:16 frames got before. The FOV decides both the heading
and the view crop's rows, so a wrong one shows the model a zoomed-in scene.

    .venv/bin/python scripts/video_fov.py runs/default/cv [--frames 80] [--mirror]

Frames: :func:`crossing_assist.data_tools.augment.phone_views` at the crop's FOV and 9:16 (three
offsets a photo; the rows a photo lacks are repeated). Scores: the model's argmax against the
moved labels (accuracy, bin MAE, >= 2 strips off; a failed inference counts as action -1, as in
``choose_gate.model_accuracy``), no decision logic.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from choose_gate import finished_folds, fold_bundle, held_out_parser, held_out_rows  # noqa: E402

from crossing_assist.data_tools.augment import phone_views  # noqa: E402
from crossing_assist.data_tools.images import load_frame  # noqa: E402
from crossing_assist.data_tools.manifest import read_manifest  # noqa: E402
from crossing_assist.geometry import default_fov  # noqa: E402


def main(argv=None) -> int:
    a = held_out_parser(__doc__.split("\n\n")[0], frames=80).parse_args(argv)
    from crossing_assist.runtime.engine import Engine

    ptl, neg = read_manifest(a.ptl), read_manifest(a.neg)
    used = {r.image for r in read_manifest(a.used_neg).rows}
    errs: dict[str, list[int]] = {}
    for fold, source in finished_folds(a.cv):
        engine = Engine(fold_bundle(fold, source, ptl, a.mirror), threads=1)
        geo = engine.bundle.geometry
        crop = default_fov(1080, 1920, geo.camera_fov_deg, geo.sensor_aspect or 4 / 3)
        fovs = {f"crop's {crop:.1f} deg": crop, f"constant {geo.camera_fov_deg[1]:g} deg": geo.camera_fov_deg[1]}
        pos, _ = held_out_rows(ptl, neg, source, used, a.frames, a.seed)
        for r in pos:
            img = load_frame(ptl.image_path(r), r.flags)
            for win, _, lab, _ in phone_views(img, r.far_x, r.label, 3, fov_deg=crop,
                                              train_fov_deg=geo.train_fov_deg, aspect=9 / 16):
                for name, fov in fovs.items():
                    p = engine.predict(win, fov)
                    errs.setdefault(name, []).append(abs((p.action if p.ok else -1) - lab))   # as model_accuracy
        print(f"fold {source}: {len(pos)} photos", file=sys.stderr, flush=True)
    if not errs:
        print(f"error: no finished fold in {a.cv}", file=sys.stderr)
        return 2
    print("| FOV read for 9:16 frames | frames | accuracy | bin MAE | >= 2 strips off |\n|---|---:|---:|---:|---:|")
    for name, e in errs.items():
        e = np.asarray(e)
        print(f"| {name} | {len(e)} | {(e == 0).mean():.3f} | {e.mean():.3f} | {(e >= 2).mean():.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
