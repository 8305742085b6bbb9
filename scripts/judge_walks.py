"""What the user heard on a set of recorded walks, judged on their labelled frames, pooled.

Each video runs through the offline demo (``crossing-demo VIDEO --labels DIR``, the model and
decision logic as a phone runs them, the turns between frames followed) with its motion-sensor
log when one lies beside it (``VIDEO.imu.csv``, as the phone app's ``?record=1`` names it). Each
labelled frame of it is judged as ``crossing-eval --bundle`` judges what the user hears
(docs/runtime.md, "Judged on a video's own labelled frames"), and the frames of all the videos
are pooled: beacon on and confidently wrong (on, >= 2 strips off) over the frames with a
crossing, silence over those without one::

    crossing-data frames walks/*.webm --fps 2 --out data/walks       # then label, then:
    crossing-data votes data/walks votes.csv export.json --test 1.0
    python scripts/judge_walks.py walks/*.webm --labels data/walks --out runs/walks

Writes ``OUT/<video>/`` (each run's trace, beacon.wav, timeline.png) and ``OUT/walks.csv`` (one
row a video, then the pooled row). A video with no labelled frame in DIR is named and left out;
none judged at all is one ``error:`` line and exit 2.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

from crossing_assist.errors import UserError, run_cli
from crossing_assist.fileio import atomic_write_text
from crossing_assist.runtime.demo import DEFAULT_BUNDLE, offset_arg
from crossing_assist.runtime.offline import OfflineConfig, run_offline
from crossing_assist.runtime.truth import LabelsError

COLUMNS = ("video", "imu", "frames_with_crossing", "beacon_on", "confidently_wrong", "accuracy_heard",
           "frames_without_crossing", "silence_no_crossing", "heading_error_median", "heading_error_p90")
COUNTED = (("beacon_on", "frames_with_crossing"), ("confidently_wrong", "frames_with_crossing"),
           ("accuracy_heard", "frames_with_crossing"), ("silence_no_crossing", "frames_without_crossing"))


def pooled(rows: list[dict]) -> dict:
    """The videos' rates pooled over their frames (each rate times its video's count, summed)."""
    out: dict = {"video": "all", "imu": ""}
    for n_key in ("frames_with_crossing", "frames_without_crossing"):
        out[n_key] = sum(r[n_key] for r in rows)
    for key, n_key in COUNTED:
        k = sum(round((r[key] or 0.0) * r[n_key]) for r in rows)
        out[key] = k / out[n_key] if out[n_key] else None
    return out


def _pct(v) -> str:
    return "n/a" if v is None else f"{100 * v:5.1f}%"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("videos", nargs="+", type=Path)
    ap.add_argument("--labels", type=Path, required=True, help="the dataset of the videos' labelled frames")
    ap.add_argument("--bundle", type=Path, default=DEFAULT_BUNDLE)
    ap.add_argument("--out", type=Path, default=Path("runs/walks"))
    ap.add_argument("--imu-offset", type=offset_arg, default=0.0, metavar="S|auto",
                    help="each log's time at its video's first frame (default 0, as the app records them)")
    ap.add_argument("--no-imu", action="store_true", help="leave the logs beside the videos out")
    a = ap.parse_args(argv)

    def run(_args) -> int:
        rows = []
        for video in a.videos:
            imu = video.with_suffix(".imu.csv")
            imu = imu if imu.is_file() and not a.no_imu else None
            try:
                s = run_offline(OfflineConfig(video=video, bundle=a.bundle, out_dir=a.out / video.stem, annotate=False,
                                              progress=False, imu=imu, imu_offset=a.imu_offset, labels=a.labels))
            except LabelsError:
                print(f"{video.name}: no labelled frame in {a.labels}; left out", file=sys.stderr)
                continue
            st, e = s.labels, s.labels["heading_error"]
            rows.append({"video": video.name, "imu": imu.name if imu else "",
                         **{k: st[k] for k in COLUMNS[2:8]}, "heading_error_median": e["median"],
                         "heading_error_p90": e["p90"]})
            print(f"{video.name:28s} crossing {st['frames_with_crossing']:4d}: on {_pct(st['beacon_on'])}, "
                  f"wrong {_pct(st['confidently_wrong'])}; none {st['frames_without_crossing']:4d}: silent "
                  f"{_pct(st['silence_no_crossing'])}" + (" (with its log)" if imu else ""))
        if not rows:
            raise UserError(f"none of the {len(a.videos)} videos has a labelled frame in {a.labels}")
        total = pooled(rows)
        print(f"{'all ' + str(len(rows)) + ' videos':28s} crossing {total['frames_with_crossing']:4d}: on "
              f"{_pct(total['beacon_on'])}, wrong {_pct(total['confidently_wrong'])}; none "
              f"{total['frames_without_crossing']:4d}: silent {_pct(total['silence_no_crossing'])}")
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        w.writerows(rows + [total])
        atomic_write_text(a.out / "walks.csv", buf.getvalue())
        print(f"table: {a.out / 'walks.csv'}")
        return 0

    return run_cli(run, [])


if __name__ == "__main__":
    sys.exit(main())
