"""The roofline's setup ceiling (benchmarks/roofline.py) computes what it claims, and its
recorded digest catches a kernel that moved. No timing is asserted here."""

import numpy as np
import pytest

from benchmarks import roofline


def _window(clip, w, h):
    ndc = clip[:, :2] / clip[:, 3:4]
    return np.stack([(ndc[:, 0] * 0.5 + 0.5) * w, (ndc[:, 1] * 0.5 + 0.5) * h], axis=1)


def test_the_ceiling_gives_the_snapped_area_and_box_of_brute_force():
    rng = np.random.default_rng(7)
    w, h, bits = 64, 48, 8
    clip = np.column_stack([rng.uniform(-1.2, 1.2, (30, 2)) * 2.0, rng.uniform(-1, 1, 30),
                            np.full(30, 2.0)])
    faces = rng.integers(0, 30, (40, 3)).astype(np.int64)
    area, box = roofline.setup_ceiling(clip, faces, w, h, bits)
    p = np.round(_window(clip, w, h) * 256 - 128).astype(np.int64)   # float64 brute force
    for t, (a, b, c) in enumerate(faces):
        (x0, y0), (x1, y1), (x2, y2) = p[a], p[b], p[c]
        assert area[t] == (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        xs, ys = np.array([x0, x1, x2]) // 256, np.array([y0, y1, y2]) // 256
        assert tuple(box[t]) == (max(xs.min(), 0), min(xs.max() + 1, w - 1),
                                 max(ys.min(), 0), min(ys.max() + 1, h - 1))


def test_the_recorded_digest_holds_and_catches_a_moved_kernel(monkeypatch):
    pytest.importorskip("trimesh")
    assert roofline.check_digests() == {}
    real = roofline.setup_ceiling

    def moved(clip, faces, *args):
        area, box = real(clip, faces, *args)
        box[:, 1] += 1             # a planted change: the box one pixel wider
        return area, box

    monkeypatch.setattr(roofline, "setup_ceiling", moved)
    assert list(roofline.check_digests()) == ["setup_ceiling/icosphere_81920"]
