"""A mesh's vertex numbering changes no output byte (benchmarks.raster ``--vertex-order``):
the renumbering keeps every face, in order, with its corners in order, and the pipeline's
outputs depend on the triangles only. No timing is asserted here."""

import numpy as np
import pytest

import refraster as rf
from benchmarks.raster import first_use_order

trimesh = pytest.importorskip("trimesh")


def _buffers(fb):
    return {k: np.asarray(a).tobytes() for k, a in fb.arrays().items()}


def test_first_use_order_keeps_the_triangles_and_numbers_in_first_use():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(50, 3))
    f = rng.integers(0, 45, (60, 3))          # vertices 45..49 and some below unused
    v2, f2 = first_use_order(v, f)
    assert np.array_equal(v2[f2], v[f])        # the same corners, face by face, in order
    flat = f2.ravel()
    _, first = np.unique(flat, return_index=True)
    assert np.array_equal(flat[np.sort(first)], np.arange(len(first)))   # 0, 1, 2, ... by use
    assert sorted(map(tuple, v2)) == sorted(map(tuple, v))                # a permutation


@pytest.mark.parametrize("normals", ["flat", "smooth"])
def test_renumbered_vertices_give_the_same_bytes(normals):
    m = trimesh.creation.icosphere(4)
    v, f = np.asarray(m.vertices), np.asarray(m.faces, np.int64)
    perm = np.random.default_rng(5).permutation(len(v))     # a scrambled numbering too
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(v))
    cam = rf.camera.frame_bounds(m.bounds, width=160, height=120, margin=1.0)
    state = rf.RasterState(normals=normals)
    frames = [_buffers(rf.render((vv, ff), view=cam.view, proj=cam.proj, width=160,
                                 height=120, raster=state))
              for vv, ff in ((v, f), first_use_order(v, f), (v[perm], inv[f]))]
    assert frames[0] == frames[1] == frames[2]
