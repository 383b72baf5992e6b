"""Fuzz harness of ``golden compare``'s candidate reading (issue 48, docs/reliability.md "The
fuzz harness").

Hypothesis draws whole candidate directories against a small golden (``render_cube`` at
32×24): ``buffers.npz`` (stored or deflated) or one ``.npy`` per buffer; per buffer kept,
dropped, cast to another dtype (value-preserving, lossy, or of a kind the buffer does not
take: ints for floats, complex, strings), reshaped, or replaced by bytes that are no ``.npy``;
members the golden does not have; a member stored twice; the archive or an ``.npy``
truncated; one pixel changed (a neighbouring float, a large step, NaN or an id far outside the
scene's). Each case is compared exactly and tolerantly and must end in exactly one of:

* **one clear error line** — exit 2, the scene ``error`` with a one-line message naming the
  file — when the candidate is unusable (a buffer missing, a wrong shape or dtype kind, no
  ``.npy``, a member twice, a truncated file), and only then;
* **a result with its property**: a candidate equal to the golden in value (casts that keep
  every value) passes — ``compare(g, g)`` passes; a candidate differing in one pixel fails, or
  (tolerant mode) passes with that pixel seen (``n_over`` 1) and forgiven by the buffer's named
  allowance checks (``n_unforgiven`` 0) — never in exact mode, never for NaN or an id outside
  the scene's; lossy casts end in a pass or a failure, not an error.

Any exception, or a warning, fails the case. CI runs ``FUZZ_EXAMPLES`` (200) examples,
derandomized; the long tier is ``REFRASTER_FUZZ_EXAMPLES=10000 python -m pytest -q -s
tests/test_fuzz_candidates.py``. The counts of each outcome are printed at the end (``-s``).
"""

from __future__ import annotations

import collections
import io
import json
import os
import re
import tempfile
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from refraster import golden
from refraster.golden.compare.run import compare

FUZZ_EXAMPLES = int(os.environ.get("REFRASTER_FUZZ_EXAMPLES", "200"))
FUZZ = settings(max_examples=FUZZ_EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
COUNTS = collections.Counter()

#: The golden's buffers, in the order of the manifest (kept fixed: strategies index them).
KEYS = ("barycentric", "color", "depth", "eye_depth", "front_facing", "normal", "object_id",
        "prim_id")
FLOAT_KINDS = ("unorm", "snorm", "float", "color")
DTYPES = ("float16", "float32", "float64", "int8", "int16", "int32", "int64", "uint8",
          "uint16", "uint32", "bool", "complex64", "S4", "<U2")


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """``(golden directory, scene name, manifest entry, buffers)`` of a 32×24 render_cube."""
    out = tmp_path_factory.mktemp("golden") / "g"
    golden.generate(out, ["render_cube"], sizes=["32x24"])
    manifest = json.loads((out / "manifest.json").read_text())
    (scene, entry), = manifest["scenes"].items()
    assert tuple(sorted(entry["buffers"])) == KEYS
    with np.load(out / scene / "buffers.npz", allow_pickle=False) as z:
        buffers = {k: z[k].copy() for k in z.files}
    return Gold((out, scene, entry, buffers))


class Gold(tuple):
    """The fixture's tuple, with a short repr (Hypothesis prints it with a failing case)."""

    def __repr__(self):
        return f"<golden {self[0]}>"


@pytest.fixture(scope="module", autouse=True)
def report_counts():
    yield
    if COUNTS:
        print("\nfuzz outcomes:", dict(sorted(COUNTS.items())))


# ---------------------------------------------------------------------------------------------
# Strategies

def _mostly(good, bad, one_in):
    return st.integers(0, one_in - 1).flatmap(lambda k: bad if k == one_in // 2 else good)


actions = _mostly(st.just(("keep",)), st.one_of(
    st.just(("drop",)), st.tuples(st.just("dtype"), st.sampled_from(DTYPES)),
    st.tuples(st.just("dtype"), st.sampled_from(DTYPES)),
    st.tuples(st.just("shape"), st.sampled_from(["transpose", "crop", "axis", "ravel",
                                                  "lead"])),
    st.just(("garbage",))), 4)
member_names = st.text("abcdefghijklmnopqrstuvwxyz0123456789_.", min_size=1, max_size=12) \
    .filter(lambda n: n.removesuffix(".npy") not in KEYS and not n.endswith("."))


@st.composite
def recipes(draw):
    """A candidate directory to build (:func:`build`) and what it must give."""
    layout = draw(st.sampled_from(["npz", "npz_deflated", "npy"]))
    damaged = draw(st.booleans())        # else every buffer is kept, nothing is cut
    keep = {k: ("keep",) for k in KEYS}
    r = dict(layout=layout, actions={k: draw(actions) for k in KEYS} if damaged else keep,
             extra=[], duplicate=None, truncate=None, pixel=None)
    if draw(st.integers(0, 3)) == 0:
        r["extra"] = draw(st.lists(member_names, max_size=3, unique=True))
    if damaged and layout != "npy" and draw(st.integers(0, 3)) == 0:
        r["duplicate"] = (draw(st.sampled_from(KEYS)), draw(st.sampled_from(["zeros", "same"])))
    if damaged and draw(st.integers(0, 3)) == 0:
        r["truncate"] = (draw(st.sampled_from(KEYS)), draw(st.floats(0.0, 0.999)))
    if draw(st.booleans()):
        r["pixel"] = (draw(st.sampled_from(KEYS)), draw(st.integers(0, 23)),
                      draw(st.integers(0, 31)),
                      draw(st.sampled_from(["next", "step", "hostile"])))
    return r


# ---------------------------------------------------------------------------------------------
# Building a candidate and what it must give

def _accepted(kind, dtype):
    """Whether the reader takes ``dtype`` for a buffer of ``kind`` (docs/golden.md)."""
    if dtype.kind not in "fiub" or dtype.itemsize > 8:
        return False
    if kind in FLOAT_KINDS:
        return dtype.kind == "f"
    if kind == "id":
        return dtype.kind in "iu"
    return dtype.kind in "iub"


def _change_pixel(a, kind, y, x, how):
    """``a`` with pixel (y, x) changed (every channel of it); ``None`` if it cannot change."""
    b = a.copy()
    old = b[y, x].copy()
    if b.dtype == np.bool_:
        b[y, x] = ~old
    elif kind == "id":
        b[y, x] = {"next": old + 1, "step": old + 7, "hostile": 1 << 30}[how]
    else:
        v = old.astype(np.float32)
        if how == "next":
            new = np.nextafter(v, np.float32(0) if np.all(np.isinf(v)) else np.float32(np.inf))
        elif how == "step":
            new = np.where(np.isfinite(v), v + np.float32(0.25), np.float32(0.5))
        else:
            new = np.full_like(v, np.nan)
        b[y, x] = new
    same = np.array_equal(b[y, x], old, equal_nan=True)
    return None if same else b


def build(root, gold, r):
    """Write the candidate of recipe ``r`` under ``root``; returns ``(directory, expected)``:
    ``expected`` is ``"refuse"``, ``"equal"`` (every value the golden's), ``"pixel"`` (one
    pixel changed, all else equal) or ``"lossy"``."""
    _, scene, entry, buffers = gold
    cand = Path(root) / "c"
    (cand / scene).mkdir(parents=True)
    refuse, lossy, members = False, False, {}
    pixel = None
    for key in KEYS:
        a, kind, action = buffers[key], entry["buffers"][key]["kind"], r["actions"][key]
        if r["pixel"] is not None and r["pixel"][0] == key and action[0] == "keep":
            changed = _change_pixel(a, kind, *r["pixel"][1:])
            if changed is not None:
                a, pixel = changed, r["pixel"]
        if action[0] == "drop":
            refuse = True
            continue
        if action[0] == "garbage":
            members[key] = b"\x93NUMPY but not really" * 3
            refuse = True
            continue
        if action[0] == "dtype":
            dtype = np.dtype(action[1])
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cast = a.astype(dtype)
                if not _accepted(kind, dtype):
                    refuse = True
                elif not np.array_equal(cast, a, equal_nan=a.dtype.kind == "f"
                                        and cast.dtype.kind == "f"):
                    lossy = True
            a = cast
        if action[0] == "shape":
            a = {"transpose": lambda v: np.swapaxes(v, 0, 1), "crop": lambda v: v[:-1],
                 "axis": lambda v: v[..., None], "ravel": np.ravel,
                 "lead": lambda v: v[None]}[action[1]](a)
            refuse = True
        bio = io.BytesIO()
        np.save(bio, a, allow_pickle=False)
        members[key] = bio.getvalue()
    for name in r["extra"]:
        bio = io.BytesIO()
        np.save(bio, np.arange(3, dtype=np.float32))
        members[name.removesuffix(".npy")] = bio.getvalue()
    if r["layout"] == "npy":
        files = {cand / scene / f"{k}.npy": v for k, v in members.items()}
    else:
        method = zipfile.ZIP_DEFLATED if r["layout"] == "npz_deflated" else zipfile.ZIP_STORED
        zbuf = io.BytesIO()
        with zipfile.ZipFile(zbuf, "w", method) as zf, warnings.catch_warnings():
            warnings.simplefilter("ignore")               # "Duplicate name"
            for k, v in members.items():
                zf.writestr(f"{k}.npy", v)
            if r["duplicate"] is not None and r["duplicate"][0] in members:
                k, how = r["duplicate"]
                second = members[k]
                if how == "zeros":
                    bio = io.BytesIO()
                    with np.errstate(all="ignore"):
                        np.save(bio, np.zeros_like(buffers[k]))
                    second = bio.getvalue()
                zf.writestr(f"{k}.npy", second)
                refuse = True
        files = {cand / scene / "buffers.npz": zbuf.getvalue()}
    if r["truncate"] is not None:
        key, frac = r["truncate"]
        path = (cand / scene / f"{key}.npy" if r["layout"] == "npy"
                else cand / scene / "buffers.npz")
        if path in files:
            files[path] = files[path][:int(len(files[path]) * frac)]
            refuse = True
    for path, data in files.items():
        path.write_bytes(data)
    expected = ("refuse" if refuse else "lossy" if lossy
                else "pixel" if pixel is not None else "equal")
    return cand, expected, pixel


# ---------------------------------------------------------------------------------------------
# The harness

def check_case(gold, r, mode):
    """Build, compare, and check the outcome's property; returns the outcome's name."""
    root, scene, entry, _ = gold
    with tempfile.TemporaryDirectory(prefix="refraster-fuzz-cand-") as tmp:
        cand, expected, pixel = build(tmp, gold, r)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            result = compare(root, cand, mode=mode)
    (s,) = result.scenes
    if result.exit_code == 2:
        assert expected == "refuse", (expected, s.error, r)
        assert s.status == "error" and s.error and "\n" not in s.error, s.error
        assert re.search(r"buffers\.npz|\.npy", s.error), s.error
        assert s.error.count("cannot read") <= 1 and "Error:" not in s.error, s.error
        return "refused: " + re.sub(r"[\d(),]+", "N", " ".join(
            s.error.split(": ", 1)[-1].split()[:4]))
    assert expected != "refuse", (result.exit_code, r)
    if expected == "equal":
        assert result.exit_code == 0, (result.summary(), r)
        return "equal values: pass"
    if expected == "lossy":
        return f"lossy cast: {['pass', 'fail'][result.exit_code]}"
    key, y, x, how = pixel
    (buf,) = [b for b in s.buffers if b.name == key]
    if result.exit_code == 1:       # (the face check of another buffer may see it too)
        assert any(not b.passed for b in s.buffers)
        return f"one pixel ({how}): fail"
    # admitted: seen, and forgiven by the buffer's named allowance checks (tolerant only)
    assert mode == "tolerant", ("exact mode admitted a changed pixel", r)
    assert how != "hostile" or entry["buffers"][key]["kind"] == "bool", r
    assert buf.metrics["n_over"] == 1 and buf.metrics["n_unforgiven"] == 0, buf.metrics
    named = entry["buffers"][key]["tolerant"]["checks"]
    assert named and {c["metric"] for c in buf.checks} == set(named), (buf.checks, named)
    return f"one pixel ({how}): admitted by {'/'.join(named)}"


@FUZZ
@given(r=recipes(), mode=st.sampled_from(["tolerant", "exact"]))
def test_candidates_end_in_one_line_or_a_result_with_its_property(small, r, mode):
    COUNTS[check_case(small, r, mode)] += 1
    COUNTS["cases"] += 1


def test_the_golden_compared_with_itself_passes_in_both_modes(small):
    root = small[0]
    for mode in ("tolerant", "exact"):
        assert compare(root, root, mode=mode).exit_code == 0


def test_the_harness_sees_a_reader_that_takes_the_second_copy(small, monkeypatch):
    """The property catches a reader that keeps a duplicate's second copy (issue 48 item 2,
    planted): the case must not pass."""
    from refraster.golden.io import read
    planted = read.read_npz

    def second_copy_wins(fh, where, error, accept):
        fh.seek(0)
        with zipfile.ZipFile(fh) as zf:
            arrays = {}
            for info in zf.infolist():
                key = info.filename.removesuffix(".npy")
                if accept(key) is not None:
                    arrays[key] = np.load(io.BytesIO(zf.read(info)), allow_pickle=False)
        return arrays, []

    r = dict(layout="npz", actions={k: ("keep",) for k in KEYS}, extra=[],
             duplicate=("depth", "zeros"), truncate=None, pixel=None)
    check_case(small, r, "exact")
    monkeypatch.setattr(read, "read_npz", second_copy_wins)
    with pytest.raises(AssertionError):
        check_case(small, r, "exact")
    monkeypatch.setattr(read, "read_npz", planted)
