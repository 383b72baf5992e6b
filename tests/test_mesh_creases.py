"""Smooth vertex normals split at creases (`Mesh.with_smooth_normals`, `split_creases`)."""

import numpy as np
import pytest
import trimesh

import refraster as rf
from refraster.mesh import Mesh, as_mesh, split_creases


def _corner_normals(v, f, n):
    return n[f]                                   # (F, 3, 3): the normal at each face corner


@pytest.mark.parametrize("sections", [13, 16, 33])
def test_cylinder_analytic(sections):
    """Side faces meet at 360°/sections (< 30°), side and caps at 90°: every rim vertex splits in
    two; side normals are exactly radial (angle weighting: each side quad contributes 90° at a
    rim vertex, however it is split into triangles), cap normals exactly ±z."""
    c = trimesh.creation.cylinder(radius=0.5, height=2.0, sections=sections)
    v, f, n, src = split_creases(c.vertices, c.faces, 30.0)
    assert len(v) == len(c.vertices) + 2 * sections
    np.testing.assert_array_equal(v, c.vertices[src])
    np.testing.assert_array_equal(v[f], c.vertices[c.faces])     # same faces, same corners
    fn = c.face_normals
    cn = _corner_normals(v, f, n)
    side = np.abs(fn[:, 2]) < 0.5
    radial = v[f][side].copy()
    radial[..., 2] = 0.0
    radial /= np.linalg.norm(radial, axis=2, keepdims=True)
    np.testing.assert_allclose(cn[side], radial, atol=1e-12)
    cap = ~side
    expect = np.sign(fn[cap, 2])[:, None, None] * np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(cn[cap], np.broadcast_to(expect, cn[cap].shape), atol=1e-12)
    # above the side-cap angle nothing splits: one copy per vertex
    v2, f2, n2, src2 = split_creases(c.vertices, c.faces, 90.5)
    assert len(v2) == len(c.vertices) and np.array_equal(np.sort(src2), np.arange(len(v2)))
    # below the side-side angle every face is its own group: flat normals
    v3, f3, n3, _ = split_creases(c.vertices, c.faces, 360.0 / sections - 0.01)
    np.testing.assert_allclose(_corner_normals(v3, f3, n3), np.repeat(fn[:, None], 3, 1),
                               atol=1e-12)


def test_box_corners_split_into_three():
    b = trimesh.creation.box()
    v, f, n, src = split_creases(b.vertices, b.faces, 30.0)
    assert len(v) == 24 and np.all(np.bincount(src) == 3)
    np.testing.assert_allclose(_corner_normals(v, f, n), np.repeat(b.face_normals[:, None], 3, 1),
                               atol=1e-15)
    # never split: the classic smoothed cube, corner normals along the diagonals
    v, f, n, _ = split_creases(b.vertices, b.faces, 180.0)
    np.testing.assert_allclose(np.abs(n), 1 / np.sqrt(3), atol=1e-15)


@pytest.mark.parametrize("make, angle", [
    (lambda: trimesh.creation.cylinder(0.4, 1.0, sections=24), 25.0),
    (lambda: trimesh.creation.annulus(0.3, 0.6, 0.5, sections=20), 40.0),
    (lambda: trimesh.creation.icosphere(2), 10.0),
    (lambda: trimesh.creation.capsule(1.0, 0.4, count=[12, 12]), 50.0),
])
def test_matches_trimesh_smooth_shade(make, angle, oracle):
    """trimesh.graph.smooth_shade disconnects faces at edges sharper than the angle and gives
    each part angle-weighted vertex normals (Thürmer & Wüthrich); where its global face
    components equal our per-vertex groups (crease lines that close), the normals at every
    face corner agree."""
    mesh = make()
    smooth = trimesh.graph.smooth_shade(mesh, angle=np.radians(angle), facet_minarea=None)
    order = np.concatenate(smooth.metadata["original_components"])
    theirs = np.empty((len(mesh.faces), 3, 3))
    theirs[order] = smooth.vertex_normals[smooth.faces]
    v, f, n, _ = split_creases(mesh.vertices, mesh.faces, angle)
    np.testing.assert_allclose(n[f], theirs, atol=1e-9)


def test_crease_ending_inside_a_surface_keeps_one_copy():
    """A cone-like fan z = A·sin(θ/2) around a centre: the only sharp edge is the spoke at
    θ = 0 (the surface's tangential slope jumps from −A/2 to +A/2 there). The crease ends at
    the centre: its faces stay joined the other way round, so the centre is not split (the
    grouping is per vertex fan, not by global components); the ring vertex on the crease,
    whose two faces meet only across it, is."""
    ring = 32
    ang = 2 * np.pi * np.arange(ring) / ring
    v = np.vstack([[0.0, 0.0, 0.0], np.c_[np.cos(ang), np.sin(ang), 2.0 * np.sin(ang / 2)]])
    f = np.array([[0, 1 + k, 1 + (k + 1) % ring] for k in range(ring)])
    fn = rf.mesh.face_normals(v, f)
    d = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", fn, np.roll(fn, 1, 0)), -1, 1)))
    crease = 0.5 * (d[0] + d[1:].max())           # d[0]: faces 31 and 0, across spoke (0, 1)
    assert d[0] > d[1:].max() + 10
    vv, ff, nn, src = split_creases(v, f, crease)
    assert np.sum(src == 0) == 1 and np.sum(src == 1) == 2
    assert np.all(np.bincount(src)[2:] == 1)


def test_mesh_option_and_render():
    c = trimesh.creation.cylinder(radius=0.5, height=2.0, sections=24)
    m = as_mesh(c).with_smooth_normals(crease_angle=30)
    assert isinstance(m, Mesh) and m.vertex_normals is not None
    assert m.n_faces == len(c.faces)
    cam = rf.camera.frame_bounds(c.bounds, width=64, height=48)
    fb = rf.render(m, **cam.kwargs, raster=rf.RasterState(normals="smooth"))
    flat = rf.render(c, **cam.kwargs)
    assert np.array_equal(fb.prim_id, flat.prim_id)           # same faces, same coverage
    # side pixels: the interpolated normal has no z component in object space, and it varies
    # continuously (flat shading has 24 constant facets)
    assert len(np.unique(np.round(fb.normal[fb.mask], 5), axis=0)) > \
        3 * len(np.unique(np.round(flat.normal[flat.mask], 5), axis=0))


@pytest.mark.parametrize("args, exc, words", [
    ((np.zeros((3, 3)), [[0, 1, 2]], -1), ValueError, "crease_angle"),
    ((np.zeros((3, 3)), [[0, 1, 2]], 181), ValueError, "crease_angle"),
    ((np.zeros((3, 3)), [[0, 1, 5]], 30), ValueError, "faces"),
    ((np.zeros((3, 2)), [[0, 1, 2]], 30), ValueError, "vertices"),
    ((np.zeros((3, 3)), [[0, 1, 2]], "30"), TypeError, "crease_angle"),
])
def test_bad_inputs(args, exc, words):
    with pytest.raises(exc, match=words):
        split_creases(*args)


def test_empty_and_degenerate():
    v, f, n, s = split_creases(np.zeros((4, 3)), np.zeros((0, 3), int), 30)
    assert v.shape == (0, 3) and f.shape == (0, 3)
    v, f, n, s = split_creases(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), [[0, 1, 2]], 30)
    assert np.all(n == 0)
