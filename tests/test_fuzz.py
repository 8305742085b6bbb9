"""Fuzzing the file readers (Hypothesis): whatever the bytes, each reader either returns or raises
its own one-line user error, never another exception type.

Readers: :func:`read_bundle` (bundle.json), :func:`read_manifest` (manifest.csv), the Label Studio
JSON and CSV vote importers, the PTL labels reader. The default suite runs a quick pass
(``QUICK`` examples per reader); ``-m slow`` runs ``LONG`` examples each.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from runtime_toy import make_toy_bundle

from crossing_assist.bundle import BundleError, read_bundle
from crossing_assist.data_tools.images import save_rgb
from crossing_assist.data_tools.manifest import ManifestError, read_manifest
from crossing_assist.data_tools.ptl import PTLError, read_ptl_labels
from crossing_assist.data_tools.votes import FrameIndex, VotesError, read_label_studio, read_votes_csv

QUICK = int(os.environ.get("FUZZ_QUICK", "60"))
LONG = int(os.environ.get("FUZZ_LONG", "3000"))
COMMON = dict(deadline=None, derandomize=False, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.function_scoped_fixture])

# ----------------------------------------------------------------------------- strategies

class HugeInt:
    """Stands for an integer over Python's str() digit limit (written as 4400 digits)."""

    def __init__(self, sign: int) -> None:
        self.sign = sign

    def __repr__(self) -> str:
        return f"HugeInt({self.sign})"


big_ints = st.one_of(st.integers(), st.integers(min_value=10 ** 20, max_value=10 ** 400),
                     st.sampled_from([HugeInt(1), HugeInt(-1)]))
scalars = st.one_of(st.none(), st.booleans(), big_ints, st.floats(allow_nan=True, allow_infinity=True),
                    st.text(max_size=40), st.sampled_from(["model.onnx", "../x.onnx", "m\x00.onnx", "", "fp32",
                                                           "entropy", "NHWC", "uint8", "RGB", "unknown", "7"]))
json_values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=12), inner, max_size=5)), max_leaves=20)


def _dumps(value) -> bytes:
    """JSON text of ``value`` (ints over Python's str() digit limit written digit by digit)."""
    def enc(v):
        if isinstance(v, bool) or v is None or isinstance(v, (float, str)):
            return json.dumps(v)
        if isinstance(v, HugeInt):
            return ("-" if v.sign < 0 else "") + "9" * 4400
        if isinstance(v, int):
            return str(v)
        if isinstance(v, list):
            return "[" + ",".join(enc(x) for x in v) + "]"
        return "{" + ",".join(json.dumps(str(k)) + ":" + enc(x) for k, x in v.items()) + "}"
    return enc(value).encode("utf-8", "surrogatepass")


def _paths(d, prefix=()):
    out = [prefix] if prefix else []
    if isinstance(d, dict):
        for k, v in d.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            out += _paths(v, prefix + (i,))
    return out


# ----------------------------------------------------------------------------- bundle.json


@pytest.fixture(scope="module")
def bundle_dir(tmp_path_factory):
    folder = make_toy_bundle(tmp_path_factory.mktemp("fuzz") / "bundle")
    return folder, json.loads((folder / "bundle.json").read_text())


def _check_bundle(folder: Path, data: bytes) -> None:
    (folder / "bundle.json").write_bytes(data)
    try:
        read_bundle(folder)
    except BundleError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 2000


def _mutate(meta, paths, path_i, value, delete):
    meta = copy.deepcopy(meta)
    path = paths[path_i % len(paths)]
    parent = meta
    for k in path[:-1]:
        parent = parent[k]
    if delete and isinstance(parent, dict):
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return meta


def _bundle_tests(n: int):
    @settings(max_examples=n, **COMMON)
    @given(path_i=st.integers(0, 10 ** 6), value=json_values, delete=st.booleans())
    def mutated(bundle_dir, path_i, value, delete):
        folder, meta = bundle_dir
        _check_bundle(folder, _dumps(_mutate(meta, _paths(meta), path_i, value, delete)))

    @settings(max_examples=n, **COMMON)
    @given(data=st.one_of(st.binary(max_size=300), json_values.map(_dumps),
                          st.integers(1, 4000).map(lambda d: b"[" * d + b"]" * d)))
    def raw(bundle_dir, data):
        _check_bundle(bundle_dir[0], data)

    return mutated, raw


test_read_bundle_mutated_fields, test_read_bundle_raw_bytes = _bundle_tests(QUICK)
_slow_mutated, _slow_raw = _bundle_tests(LONG)
test_read_bundle_mutated_fields_long = pytest.mark.slow(_slow_mutated)
test_read_bundle_raw_bytes_long = pytest.mark.slow(_slow_raw)


# ----------------------------------------------------------------------------- CSV readers

cells = st.one_of(st.text(max_size=30), st.sampled_from(["", "7", "unknown", "0.5", "train", "val", "a.png",
                                                          "images/a.png", "ptl:x", "6:3 7:1", "nan", "-1", "13",
                                                          "a\x00.png", "x" * 300, "../a.png", "/abs.png"]))
csv_lines = st.lists(st.lists(cells, min_size=0, max_size=9).map(
    lambda row: ",".join('"' + c.replace('"', '""') + '"' if ("," in c or '"' in c or "\n" in c) else c
                         for c in row)), max_size=6)
csv_bodies = st.one_of(st.binary(max_size=400), csv_lines.map(lambda ls: "\n".join(ls).encode("utf-8",
                                                                                                "surrogatepass")),
                       st.just(b"x" * 140_000))

MANIFEST_HEAD = b"image,label,far_x,source,split,votes,flags\n"
PTL_HEAD = b"image,split,photographer,far_x,bin12,blocked,light\n"
VOTES_HEAD = b"frame,annotator,label\n"


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzzcsv")
    save_rgb(root / "a.png", np.zeros((8, 8, 3), np.uint8))
    save_rgb(root / "images" / "a.png", np.zeros((8, 8, 3), np.uint8))
    return root


def _headed(data: bytes, head: bytes, with_head: bool) -> bytes:
    return head + data if with_head else data


def _csv_tests(n: int):
    @settings(max_examples=n, **COMMON)
    @given(data=csv_bodies, with_head=st.booleans(), check=st.booleans())
    def manifest(work, data, with_head, check):
        (work / "manifest.csv").write_bytes(_headed(data, MANIFEST_HEAD, with_head))
        try:
            read_manifest(work, check_images=check)
        except ManifestError as exc:
            assert "\n" not in str(exc)

    @settings(max_examples=n, **COMMON)
    @given(data=csv_bodies, with_head=st.booleans())
    def ptl(work, data, with_head):
        (work / "labels.csv").write_bytes(_headed(data, PTL_HEAD, with_head))
        try:
            read_ptl_labels(work)
        except PTLError as exc:
            assert "\n" not in str(exc)

    @settings(max_examples=n, **COMMON)
    @given(data=csv_bodies, with_head=st.booleans())
    def votes_csv(work, data, with_head):
        (work / "votes.csv").write_bytes(_headed(data, VOTES_HEAD, with_head))
        try:
            read_votes_csv(work / "votes.csv", FrameIndex(["v1/a.png", "v2/b.jpg"]))
        except VotesError as exc:
            assert "\n" not in str(exc)

    return manifest, ptl, votes_csv


test_read_manifest, test_read_ptl_labels, test_read_votes_csv = _csv_tests(QUICK)
_m, _p, _v = _csv_tests(LONG)
test_read_manifest_long, test_read_ptl_labels_long, test_read_votes_csv_long = (
    pytest.mark.slow(_m), pytest.mark.slow(_p), pytest.mark.slow(_v))


# ----------------------------------------------------------------------------- Label Studio

ls_choice = st.one_of(st.sampled_from(["7", "unknown", "13", ""]), json_values)
ls_result = st.one_of(json_values, st.fixed_dictionaries(
    {"type": st.sampled_from(["choices", "labels"]), "value": st.one_of(json_values, st.fixed_dictionaries(
        {"choices": st.one_of(json_values, st.lists(ls_choice, max_size=3))}))}))
ls_annotation = st.one_of(json_values, st.fixed_dictionaries(
    {"id": json_values, "result": st.one_of(json_values, st.lists(ls_result, max_size=3))},
    optional={"completed_by": json_values, "was_cancelled": json_values}))
ls_task = st.one_of(json_values, st.fixed_dictionaries(
    {"id": json_values, "data": st.one_of(json_values, st.fixed_dictionaries(
        {"image": st.one_of(json_values, st.sampled_from(["a.png", "/data/upload/4/8f3a2b1c-a.png",
                                                          "/data/local-files/?d=v1/a.png", "b.jpg"]))}))},
    optional={"annotations": st.one_of(json_values, st.lists(ls_annotation, max_size=3))}))
ls_exports = st.one_of(st.lists(ls_task, max_size=4).map(_dumps), json_values.map(_dumps), st.binary(max_size=200))


def _ls_tests(n: int):
    @settings(max_examples=n, **COMMON)
    @given(data=ls_exports)
    def label_studio(work, data):
        (work / "ls.json").write_bytes(data)
        try:
            read_label_studio(work / "ls.json", FrameIndex(["v1/a.png", "v2/b.jpg"]))
        except VotesError as exc:
            assert "\n" not in str(exc)

    return label_studio


test_read_label_studio = _ls_tests(QUICK)
test_read_label_studio_long = pytest.mark.slow(_ls_tests(LONG))


def test_fuzz_inputs_reach_the_readers(work):
    """The strategies produce inputs the readers accept, too (so the fuzzing is not all noise)."""
    (work / "manifest.csv").write_bytes(MANIFEST_HEAD + b"a.png,7,0.55,ptl:x,train,,\n")
    assert len(read_manifest(work)) == 1
    (work / "labels.csv").write_bytes(PTL_HEAD + b"images/a.png,train,x,0.55,7,0,1\n")
    assert len(read_ptl_labels(work)) == 1
    export = [{"id": 1, "data": {"image": "a.png"},
               "annotations": [{"id": 1, "result": [{"type": "choices", "value": {"choices": ["7"]}}]}]}]
    (work / "ls.json").write_bytes(_dumps(export))
    assert len(read_label_studio(work / "ls.json", FrameIndex(["v1/a.png"]))) == 1
    with tempfile.TemporaryDirectory():
        pass
