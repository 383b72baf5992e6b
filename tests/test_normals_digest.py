"""The smooth-normals cache's key (`refraster.mesh._mesh_digest`): large meshes are hashed in two
halves on two threads; the key must still change with any byte of the mesh, or a mesh changed
in place would be drawn with its old normals."""

import numpy as np
import pytest
import trimesh

from refraster import mesh as mesh_module
from refraster.mesh import _mesh_digest, as_mesh, smooth_normals, vertex_normals


@pytest.fixture(params=["flat", "halves"])
def split(request, monkeypatch):
    """The digest as small meshes take it (one pass) and as large ones do (two halves)."""
    if request.param == "halves":
        monkeypatch.setattr(mesh_module, "_DIGEST_SPLIT", 0)
    return request.param


def _mesh():
    t = trimesh.creation.icosphere(3)
    return np.array(t.vertices, np.float64), np.array(t.faces, np.int64)


def test_the_key_changes_with_every_byte_and_only_with_a_byte(split):
    v, f = _mesh()
    key = _mesh_digest(v, f)
    assert _mesh_digest(v.copy(), f.copy()) == key               # the same bytes elsewhere
    nv, nf = v.nbytes, f.nbytes
    total = nv + nf
    # bytes around the halves' boundary, at both ends and in both arrays
    for pos in sorted({0, nv - 1, nv, total // 2 - 1, total // 2, total // 2 + 1, total - 1}):
        v2, f2 = v.copy(), f.copy()
        raw = (v2.view(np.uint8).reshape(-1) if pos < nv else f2.view(np.uint8).reshape(-1))
        raw[pos if pos < nv else pos - nv] ^= 1
        assert _mesh_digest(v2, f2) != key, pos
    # the same bytes in other shapes (the last vertex's 24 bytes moved to the faces' front):
    # the shapes are hashed too
    f2 = np.frombuffer(v[-1].tobytes() + f.tobytes(), np.int64).reshape(-1, 3)
    assert _mesh_digest(v[:-1], f2) != key


def test_normals_follow_a_large_mesh_changed_in_place(split):
    v, f = _mesh()
    m = as_mesh((v, f))
    first = smooth_normals(m).copy()
    f[-1] = f[-1][::-1]   # the last face turned: its bytes are in the second half when split
    np.testing.assert_array_equal(smooth_normals(m), vertex_normals(v, f))
    assert not np.array_equal(smooth_normals(m), first)


def test_the_key_does_not_depend_on_the_thread_count(monkeypatch):
    """A frame on one thread (busy cores) hashes the halves one after the other: the same key,
    so that frames alternating between one and two threads keep hitting the cache."""
    import numba
    monkeypatch.setattr(mesh_module, "_DIGEST_SPLIT", 0)
    v, f = _mesh()
    old = numba.get_num_threads()
    keys = []
    try:
        for n in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(n)
            keys.append(_mesh_digest(v, f))
    finally:
        numba.set_num_threads(old)
    assert keys[0] == keys[1]
