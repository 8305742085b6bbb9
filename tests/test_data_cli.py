"""The crossing-data parser's defaults agree with the library's config dataclasses."""

from pathlib import Path

from crossing_assist.data_tools.augment_dataset import AugmentConfig
from crossing_assist.data_tools.cli import build_parser, main
from crossing_assist.data_tools.frames import FramesConfig
from crossing_assist.data_tools.labels import VotesConfig
from crossing_assist.data_tools.ptl import PTLImportConfig
from crossing_assist.data_tools.splits import SplitConfig
from crossing_assist.data_tools.synth import ClipConfig, SynthConfig


def _parse(*argv):
    return build_parser().parse_args(list(argv))


def test_cli_defaults_match_configs():
    a = _parse("frames", "v.mp4", "--out", "o")
    assert a.fps == FramesConfig((), Path(".")).fps
    a = _parse("import-ptl", "p", "--out", "o")
    assert a.images == PTLImportConfig(Path("."), Path(".")).images
    a = _parse("votes", "f", "v.csv")
    d = VotesConfig(Path("."), ())
    assert (a.tie, a.min_votes, a.val, a.test, a.seed) == (d.tie, d.min_votes, d.split.val, d.split.test, d.split.seed)
    a = _parse("split", "ds")
    assert (a.val, a.test, a.seed) == (SplitConfig().val, SplitConfig().test, SplitConfig().seed)
    a = _parse("augment", "ds", "--out", "o")
    d = AugmentConfig(Path("."), Path("."))
    assert (not a.no_mirror, tuple(a.yaw), a.fov, a.out_of_frame, tuple(a.splits), a.drop_unknown) == \
        (d.mirror, d.yaw_deg, d.fov_deg, d.out_of_frame, d.splits, d.drop_unknown_yaw)
    a = _parse("synth", "--out", "o")
    s, c = SynthConfig(Path(".")), ClipConfig(Path("c.mp4"))
    assert (a.frames, a.seed, a.fov, a.unknown_fraction, a.val_fraction, a.supersample, a.lookalike_fraction) == \
        (s.frames, s.seed, s.fov_deg, s.unknown_fraction, s.val_fraction, s.supersample, s.lookalike_fraction)
    assert (a.seconds, a.fps) == (c.seconds, c.fps)


def test_main_returns_two_on_user_error(tmp_path, capsys):
    assert main(["stats", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
