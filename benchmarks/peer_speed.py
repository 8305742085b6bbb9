"""The bundle against LYTNet (PTL's peer model), side by side: how many times faster per frame.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/peer_speed.py [--bundle DIR] [--int8] [--data DIR]
        [--no-v2] [--rounds 15] [--block 3] [--frame 640x480]

Models, all under the same onnxruntime session options (1 intra-op thread, sequential, full
graph optimisation), timed by the calling thread's CPU time, rounds interleaved (each round
runs every model for ``--block`` calls):

* ``bundle``: the bundle's ``model.onnx`` (default: the embedded default bundle) on one uint8
  RGB frame of ``--frame`` size (640x480): the graph resizes and normalises it to the bundle's
  canvas (``input.size`` in bundle.json), runs the backbone once and the head's T MC samples;
* ``bundle int8`` (``--int8``, fp32 bundles only): the same graph quantised as
  ``crossing-export --int8`` does, calibrated on ``--data``'s val frames (else synthetic
  frames: timing only);
* ``LYTNet V1 proxy``: torchvision's ``mobilenet_v2`` trunk at width 1.0 with a 2x2 max-pool
  after the stem convolution (LYTNet V1's layout), global pool and two linear heads (5 light
  classes, 4 midline coordinates), random weights, on a ready-made 1x3x576x768 float input
  (no resize or normalisation charged to it);
* ``LYTNet V2 proxy`` (unless ``--no-v2``): the same with torchvision's
  ``mobilenet_v3_large`` trunk (a MobileNetV3-Large-style layout) and the same stem pool.

Prints the median ms per call of each and, for each LYTNet proxy, the median per-round ratio
proxy/bundle (> 1: the bundle is faster). Absolute ms depend on the machine's load; quote
the ratios. The proxies time the architecture, not LYTNet's trained weights.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from speedlib import int8_split, interleaved, load_split, parse_size, ratio, session, synthetic_frames  # noqa: E402

from crossing_assist.bundle import BundleError, read_bundle  # noqa: E402

DEFAULT_BUNDLE = Path(__file__).resolve().parents[1] / "crossing_assist" / "assets" / "default_bundle"
LYTNET_INPUT = (576, 768)  # H, W


def lytnet_proxy(version: int):
    """torch module: a LYTNet-layout trunk (random weights) with the 2x2 max-pool after the stem."""
    import torch
    from torch import nn
    from torchvision.models import mobilenet_v2, mobilenet_v3_large

    trunk = mobilenet_v2(weights=None, width_mult=1.0) if version == 1 else mobilenet_v3_large(weights=None)
    feats = list(trunk.features)
    layers = nn.Sequential(feats[0], nn.MaxPool2d(2, 2), *feats[1:])
    channels = feats[-1].out_channels if hasattr(feats[-1], "out_channels") else feats[-1][0].out_channels

    class Proxy(nn.Module):
        def __init__(self):
            super().__init__()
            self.features = layers
            self.light = nn.Linear(channels, 5)
            self.direction = nn.Linear(channels, 4)

        def forward(self, x):
            f = torch.flatten(nn.functional.adaptive_avg_pool2d(self.features(x), 1), 1)
            return self.light(f), self.direction(f)

    torch.manual_seed(version)
    return Proxy().eval()


def export_proxy(version: int, path: Path) -> None:
    import torch

    example = torch.zeros(1, 3, *LYTNET_INPUT)
    with torch.no_grad():
        program = torch.onnx.export(lytnet_proxy(version), (example,), input_names=["x"],
                                    output_names=["light", "direction"], dynamo=True, external_data=False,
                                    opset_version=18, verbose=False, optimize=True)
    program.save(str(path))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bundle", default=str(DEFAULT_BUNDLE), help="bundle folder (default: the embedded one)")
    p.add_argument("--int8", action="store_true", help="also time the bundle quantised to int8 (static)")
    p.add_argument("--data", help="dataset folder (manifest.csv): val frames to calibrate --int8 on")
    p.add_argument("--calib-frames", type=int, default=128)
    p.add_argument("--no-v2", action="store_true", help="skip the LYTNet V2 (MobileNetV3-Large-style) proxy")
    p.add_argument("--frame", type=parse_size, default=(640, 480), help="bundle's frame WIDTHxHEIGHT (640x480)")
    p.add_argument("--rounds", type=int, default=15)
    p.add_argument("--block", type=int, default=3)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        bundle = read_bundle(args.bundle)
    except (BundleError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.int8 and bundle.precision != "fp32":
        print(f"error: --int8 needs an fp32 bundle; {args.bundle} is {bundle.precision}", file=sys.stderr)
        return 2
    fw, fh = args.frame
    frame = {"frames": synthetic_frames(1, fh, fw, seed=1)[0][None]}
    h, w = bundle.input.size
    name = f"bundle {bundle.precision}"
    models = {name: (session(str(bundle.model_path)), frame)}
    if args.int8:
        import onnx

        from crossing_assist.export.graph import model_bytes
        from crossing_assist.export.quantize import quantize_convs

        if args.data:
            data = load_split(args.data, "val", bundle.actions.n)
            calib = [data.images[i] for i in int8_split(len(data.images), args.calib_frames)[0]]
        else:
            calib = synthetic_frames(args.calib_frames, 240, 320)
        q = quantize_convs(onnx.load_model(str(bundle.model_path)), calib)
        models["bundle int8"] = (session(model_bytes(q)), frame)
    x = {"x": np.random.default_rng(0).normal(0, 1, (1, 3, *LYTNET_INPUT)).astype(np.float32)}
    peers = ["LYTNet V1 proxy"] + ([] if args.no_v2 else ["LYTNet V2 proxy"])
    with tempfile.TemporaryDirectory(prefix="peer-speed-") as tmp:
        for i, peer in enumerate(peers, start=1):
            path = Path(tmp) / f"lytnet_v{i}.onnx"
            export_proxy(i, path)
            models[peer] = (session(str(path)), x)
        timed = interleaved(models, rounds=args.rounds, block=args.block)

    print(f"1 onnxruntime thread, thread CPU time, {args.rounds} interleaved rounds of {args.block} calls")
    print(f"  {name}: one {fw}x{fh} uint8 frame -> resize/normalise to {h}x{w} (HxW) + backbone + "
          f"{bundle.mc.samples} MC head samples: median {np.median(timed[name].ms):.2f} ms")
    if "bundle int8" in timed:
        print(f"  bundle int8 (static, quantised here): median {np.median(timed['bundle int8'].ms):.2f} ms "
              f"({ratio(timed[name], timed['bundle int8']):.2f}x faster than {name})")
    for peer in peers:
        print(f"  {peer}: 1x3x{LYTNET_INPUT[0]}x{LYTNET_INPUT[1]} float input ready-made, random weights: "
              f"median {np.median(timed[peer].ms):.2f} ms")
    print("speed-up over each peer (median of per-round ratios, > 1: faster than the peer):")
    for peer in peers:
        cells = [f"{b} {ratio(timed[peer], timed[b]):.2f}x" for b in timed if b.startswith("bundle")]
        print(f"  vs {peer}: " + ", ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
