"""Robustness of bundles to field corruptions: accuracy and what the user hears, per corruption.

Every val photo (true aspect) is corrupted by each of :data:`crossing_assist.data_tools.corrupt.CORRUPTIONS`
(strength drawn from a generator seeded per photo and corruption, identical for every bundle)
and run through each bundle (one engine pass, T MC samples). Printed side by side: accuracy
(13 actions), bin MAE and the share of frames whose argmax is >= 2 strips off with the gate
open (uncertainty under the bundle's threshold), for the clean photos and each corruption.

    .venv/bin/python benchmarks/robustness.py --data runs/data/ptl --bundles old=/tmp/old_bundle \
        new=crossing_assist/assets/default_bundle --frames 300
"""

from __future__ import annotations

import argparse
import sys
import zlib

import numpy as np

from crossing_assist.actions import UNKNOWN
from crossing_assist.data_tools.corrupt import CORRUPTIONS, corrupt
from crossing_assist.data_tools.images import load_frame
from crossing_assist.data_tools.manifest import read_manifest
from crossing_assist.runtime.engine import Engine


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="runs/data/ptl")
    ap.add_argument("--split", default="val")
    ap.add_argument("--bundles", nargs="+", required=True, help="NAME=DIR ...")
    ap.add_argument("--frames", type=int, default=300, help="photos (evenly spread over the split)")
    a = ap.parse_args(argv)
    ds = read_manifest(a.data).split(a.split)
    rows = [r for r in ds.rows if r.label != UNKNOWN]
    rows = [rows[i] for i in np.linspace(0, len(rows) - 1, min(a.frames, len(rows))).astype(int)]
    engines = {}
    for spec in a.bundles:
        name, _, path = spec.partition("=")
        engines[name] = Engine(path, threads=1)
    names = ["clean", *CORRUPTIONS]
    stats = {(b, c): [] for b in engines for c in names}
    for r in rows:
        img = load_frame(ds.image_path(r), r.flags)
        for c in names:
            rng = np.random.default_rng([zlib.crc32(r.image.encode()), names.index(c)])
            frame = img if c == "clean" else corrupt(img, c, rng)
            for b, eng in engines.items():
                p = eng.predict(frame)
                a_ = p.action if p.ok else 0
                err = abs(a_ - r.label) if a_ else None
                # the gate threshold of the frame's own orientation and FOV (a per-frame stand-in for the gate)
                thr = eng.decision_config(p.orientation, p.fov_deg).threshold if p.ok else 0.0
                stats[b, c].append((a_ == r.label, err, p.ok and p.uncertainty < thr and a_ != 0 and err >= 2))
    print(f"{len(rows)} {a.split} photos of {a.data}; per corruption: accuracy / bin MAE (known predictions) / "
          f"confidently wrong (gate open, >= 2 strips off)")
    print(f"{'corruption':<14}" + "".join(f"{b:>30}" for b in engines))
    for c in names:
        cells = []
        for b in engines:
            s = stats[b, c]
            acc = np.mean([x[0] for x in s])
            errs = [x[1] for x in s if x[1] is not None]
            wrong = np.mean([x[2] for x in s])
            cells.append(f"{acc:8.3f} / {np.mean(errs) if errs else float('nan'):5.2f} / {100 * wrong:5.1f} %")
        print(f"{c:<14}" + "".join(f"{x:>30}" for x in cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
