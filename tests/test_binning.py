"""The binning: the primitive stage's per-chunk tile counts and the tile lists, against a
brute force in NumPy (every face's box and every clipped piece's box, tile by tile)."""

import numpy as np
import pytest
import trimesh

import refraster as rf
from refraster.raster import _prepare
from refraster.raster.primitive import BIN_CHUNK, CLIPPED, SIMPLE, TILE_SHIFT, bin_shape
from refraster.raster.rasterizer import bin_primitives


def _items(p):
    """Every binned item in primitive order with its pixel box: simple face i, clipped piece
    k as −(k + 1)."""
    st = p.clipped
    out = []
    for i in range(p.n_faces):
        if p.status[i] == SIMPLE:
            out.append((i, i, p.bbox[i]))
        elif p.status[i] == CLIPPED:
            for k in np.flatnonzero(st.prim == i):
                out.append((i, -(int(k) + 1), st.bbox[k]))
    return out


def _brute(p):
    nchunks, ntx, nty = bin_shape(p.n_faces, p.width, p.height)
    counts = np.zeros((nchunks, ntx * nty), np.int64)
    lists = [[] for _ in range(ntx * nty)]
    for face, item, box in _items(p):
        x0, x1, y0, y1 = (int(v) >> TILE_SHIFT for v in box)
        for ty in range(y0, y1 + 1):
            for tx in range(x0, x1 + 1):
                counts[face // BIN_CHUNK, ty * ntx + tx] += 1
                lists[ty * ntx + tx].append(item)
    return counts, lists


def _scenes():
    """Faces over several chunks, interleaving skipped and simple faces (a fine sphere: most
    of its faces cover no pixel centre), clipped by the near plane (pieces), boxes over
    several tiles, culled faces, and the multisampling's padded boxes."""
    rng = np.random.default_rng(7)
    fine = trimesh.creation.icosphere(5)          # 20 480 faces: three chunks
    coarse = trimesh.creation.icosphere(2)        # boxes over several tiles
    # near 2.5 from an eye 3 away: the near plane cuts the sphere in view
    for mesh, near, kw in ((fine, 0.5, {}), (coarse, 0.5, {}), (fine, 2.5, {}),
                           (coarse, 2.5, {}), (fine, 0.5, {"cull": "back"}),
                           (coarse, 2.5, {"samples": 4})):
        rot = trimesh.transformations.random_rotation_matrix(rng.random(3))
        v = trimesh.transform_points(mesh.vertices, rot)
        view = rf.camera.look_at(eye=(0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0))
        proj = rf.camera.perspective(60.0, 300 / 200, near, 10.0)
        yield (v, np.asarray(mesh.faces)), view, proj, rf.RasterState(**kw)


@pytest.mark.parametrize("case", range(6))
def test_primitive_stage_counts_and_tile_lists_match_a_brute_force(case):
    mesh, view, proj, state = list(_scenes())[case]
    prep = _prepare([rf.mesh.as_mesh(mesh)], view=view, proj=proj, width=300, height=200,
                    model=None, state=state, scratch=None, multisample=state.samples > 1)
    p = prep.triangles
    counts, lists = _brute(p)
    assert counts.sum() > 0
    if case in (2, 3, 5):
        assert (p.status == CLIPPED).any() and len(p.clipped.prim)   # pieces counted too
    np.testing.assert_array_equal(p.tile_counts, counts)
    _, _, starts, got = bin_primitives(p)
    assert len(got) == starts[-1] == counts.sum()   # no junk slot handed out
    for t, want in enumerate(lists):
        assert got[starts[t]:starts[t + 1]].tolist() == want, t
