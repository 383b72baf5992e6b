"""Ghost lines of the removed structure (Burns & Finkelstein Sec. 4.3, Fig. 4d–e; MATH.md D-C11;
issue 23 point 1).

The scene: a sphere (the object of interest) inside two nested box shells. The expected lines
come from the boxes' analytic corners, not from the meshes: each of the 4 boxes (outer and inner
surface of each shell) has 12 edges, all at 90° — every one is a crease or a silhouette. They are
sampled densely in world space, projected with the camera matrices here, and their eye depth is
−z of the view transform (not the NDC conversion the implementation uses). The cutaway surface
D is read from the framebuffer (float32 window depth), converted to eye depth by the closed
form of the projection.
"""

import numpy as np
import pytest

import refraster as rr
from refraster.cutaway import Cutaway, GhostLines, render_cutaway
from refraster.scenes import cube, icosphere

G_MAX = 1.0
HALF = (1.2, 1.05, 0.8, 0.68)          # shell 1 = 1.2 / 1.05, shell 2 = 0.8 / 0.68


def box(a, flip=False):
    c = cube(1.0)
    f = np.asarray(c.faces)
    return np.asarray(c.vertices) * (2 * a), (f[:, ::-1] if flip else f)


def shell(a, b):
    v1, f1 = box(a)
    v2, f2 = box(b, flip=True)
    return np.concatenate([v1, v2]), np.concatenate([f1, f2 + len(v1)])


SHELLS = [shell(HALF[0], HALF[1]), shell(HALF[2], HALF[3])]
OOI = [icosphere(2, radius=0.3)]
NEAR, FAR = 1.0, 12.0

CAMERAS = {
    "persp_corner": dict(view=rr.look_at((2.8, 2.2, 3.4), (0, 0, 0)),
                         proj=rr.perspective(40, 1.0, NEAR, FAR), width=160, height=160),
    "persp_low": dict(view=rr.look_at((-3.6, -1.3, 2.6), (0, 0.1, 0)),
                      proj=rr.perspective(45, 1.25, NEAR, FAR), width=180, height=144),
    "ortho": dict(view=rr.look_at((3.0, 2.4, 3.3), (0, 0, 0)),
                  proj=rr.orthographic(-1.8, 1.8, -1.8, 1.8, NEAR, FAR), width=150, height=150),
}


def analytic_edges():
    """(48, 2, 3) edges of the four boxes and the shell each belongs to."""
    edges, owner = [], []
    for k, a in enumerate(HALF):
        corners = np.array([[x, y, z] for x in (-a, a) for y in (-a, a) for z in (-a, a)])
        for i in range(8):
            for j in range(i + 1, 8):
                if np.count_nonzero(corners[i] != corners[j]) == 1:
                    edges.append((corners[i], corners[j]))
                    owner.append(k // 2)
    return np.array(edges), np.array(owner)


def eye_depth_of_ndc(z, proj):
    """Closed form per camera kind (glFrustum / glOrtho with NEAR, FAR)."""
    if proj[3, 3] == 0:
        return 2 * NEAR * FAR / ((FAR + NEAR) - z * (FAR - NEAR))
    return NEAR + (z + 1) * 0.5 * (FAR - NEAR)


def expected_lines(fb, cam, g_max=G_MAX, samples=3000):
    """Per sample of every analytic edge: pixel, expected α (NaN if not a ghost line there)."""
    view, proj, w, h = cam["view"], cam["proj"], cam["width"], cam["height"]
    edges, owner = analytic_edges()
    t = (np.arange(samples) + 0.5) / samples
    pts = edges[:, :1] + t[None, :, None] * (edges[:, 1:] - edges[:, :1])        # (E, S, 3)
    eye = pts @ view[:3, :3].T + view[:3, 3]
    clip = np.concatenate([eye, np.ones(eye.shape[:2] + (1,))], -1) @ proj.T
    ndc = clip[..., :3] / clip[..., 3:]
    x = (ndc[..., 0] + 1) * 0.5 * w
    y = (1 - ndc[..., 1]) * 0.5 * h
    col = np.floor(x).astype(int)
    row = np.floor(y).astype(int)
    on = (col >= 0) & (col < w) & (row >= 0) & (row < h) & (np.abs(ndc[..., 2]) <= 1)
    col, row = np.clip(col, 0, w - 1), np.clip(row, 0, h - 1)
    d_ndc = 2.0 * fb.cutaway_depth.astype(np.float64)[row, col] - 1.0
    gap = eye_depth_of_ndc(d_ndc, proj) - (-eye[..., 2])
    removed = on & (ndc[..., 2] < d_ndc)
    ooi = (fb.object_id[row, col] >= len(SHELLS)) & \
        (2.0 * fb.depth.astype(np.float64)[row, col] - 1.0 < ndc[..., 2])
    ghost = removed & ~ooi & (gap < g_max)
    alpha = np.where(ghost, 1.0 - gap / g_max, np.nan)
    return dict(row=row, col=col, gap=gap, ghost=ghost, alpha=alpha, owner=owner, on=on,
                removed=removed & ~ooi, x=x, y=y)


def check(image_alpha, exp, g_max=G_MAX, tol=0.05):
    """(worst per-edge coverage, edges checked, stray ghost pixels)."""
    h, w = image_alpha.shape
    row, col, ghost, alpha = exp["row"], exp["col"], exp["ghost"], exp["alpha"]
    # the expected opacity of a pixel is the largest over the lines crossing it; a line that
    # only grazes a pixel's corner (closer than the sample spacing) may add its own α there, so
    # the upper bound also takes the lines passing within 0.1 px of the pixel
    best = np.full((h, w), -1.0)
    np.maximum.at(best, (row[ghost], col[ghost]), alpha[ghost])
    loose = best.copy()
    for dx in (-0.1, 0.1):
        for dy in (-0.1, 0.1):
            c = np.floor(exp["x"][ghost] + dx).astype(int)
            r = np.floor(exp["y"][ghost] + dy).astype(int)
            ok = (c >= 0) & (c < w) & (r >= 0) & (r < h)
            np.maximum.at(loose, (r[ok], c[ok]), alpha[ghost][ok])
    # away from the exact cut boundary (float32 D) the samples must show with the formula's α
    judged = ghost & (exp["gap"] > 1e-3)
    coverage = []
    for e in range(len(row)):
        s = judged[e]
        if s.sum() < 30:                 # < 1 % of the edge in the band: nothing to judge
            continue
        got = image_alpha[row[e, s], col[e, s]]
        lo, hi = best[row[e, s], col[e, s]] - tol, loose[row[e, s], col[e, s]] + tol
        coverage.append(np.mean((got >= lo) & (got <= hi)))
    # nothing beyond g_max: every ghost pixel lies within 1 px of a line sample in the band
    band = np.zeros((h, w), bool)
    band[row[ghost], col[ghost]] = True
    near = band.copy()
    near[1:] |= band[:-1]
    near[:-1] |= band[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    stray = int(np.count_nonzero((image_alpha > 0) & ~near))
    return (min(coverage) if coverage else 0.0), len(coverage), stray


def silhouettes(cam):
    """Which analytic edges are silhouettes: their two faces (normals along the axes) face
    opposite ways as seen from the eye (the inverted inner boxes flip both: same answer)."""
    inv = np.linalg.inv(cam["view"])
    edges, _ = analytic_edges()
    out = []
    for a, b in edges:
        mid = 0.5 * (a + b)
        toward = inv[:3, 2] if cam["proj"][3, 3] == 1 else inv[:3, 3] - mid
        axes = [i for i in range(3) if a[i] == b[i]]
        facing = [np.sign(mid[i]) * toward[i] > 0 for i in axes]
        out.append(facing[0] != facing[1])
    return np.array(out)


@pytest.fixture(scope="module", params=[(c, a) for c in sorted(CAMERAS) for a in (0.5, 1.0)],
                ids=lambda p: f"{p[0]}-theta{p[1]}")
def rendered(request):
    name, angle = request.param
    cam = CAMERAS[name]
    fb = render_cutaway(OOI, SHELLS, **cam, cutaway=Cutaway(angle=angle),
                        ghosts=GhostLines(distance=G_MAX))
    exp = expected_lines(fb, cam)
    exp["angle"] = angle
    exp["silhouette"] = silhouettes(cam)
    return cam, fb, exp


def test_every_removed_crease_and_silhouette_shows_with_the_fade(rendered):
    cam, fb, exp = rendered
    # the cut carves both shells, and lines of both lie in the fade band
    for k in (0, 1):
        assert exp["ghost"][exp["owner"] == k].sum() > 200
    worst, n_edges, stray = check(fb.ghost, exp)
    assert n_edges >= 6
    assert worst >= 0.95, worst
    assert stray == 0
    # the wide cut reaches the inner shell's outline: silhouettes are judged, not only creases
    judged = (exp["ghost"] & (exp["gap"] > 1e-3)).sum(axis=1) >= 30
    if exp["angle"] >= 1.0:
        assert np.count_nonzero(judged & exp["silhouette"]) >= 4
    assert np.count_nonzero(judged & ~exp["silhouette"]) >= 6
    # removed lines beyond g_max exist in this scene and stay invisible
    beyond = exp["removed"] & (exp["gap"] > G_MAX + 0.05)
    assert beyond.sum() > 100
    r, c = exp["row"][beyond], exp["col"][beyond]
    band = np.zeros(fb.ghost.shape, bool)
    band[exp["row"][exp["ghost"]], exp["col"][exp["ghost"]]] = True
    assert np.all(fb.ghost[r, c][~band[r, c]] == 0)


def test_planted_faults_fail(rendered, monkeypatch):
    cam, fb, exp = rendered
    # (1) the first visible surface only (the former implementation) misses hidden lines
    cut = Cutaway(angle=exp["angle"])
    first = render_cutaway(OOI, SHELLS, **cam, cutaway=cut,
                           ghosts=GhostLines(source="visible", distance=G_MAX))
    assert check(first.ghost, exp)[0] < 0.95
    # (2) the fade with the wrong sign: α = (D − z)/g_max
    flipped = np.where(fb.ghost > 0, 1.0 - fb.ghost, 0.0)
    assert check(flipped, exp)[0] < 0.95
    # (3) no distance limit: lines beyond g_max show
    far = render_cutaway(OOI, SHELLS, **cam, cutaway=cut,
                         ghosts=GhostLines(distance=3 * G_MAX, fade=False))
    assert check(far.ghost, exp)[2] > 0
    # (5) the right lines, but only where they lie on the first layer (the removed surfaces
    # hiding each other, as one z-buffered pass over the uncut scene would)
    import refraster.cutaway.render as render_mod
    first_layer = 2.0 * rr.render(SHELLS, **cam).depth.astype(np.float64) - 1.0
    original = render_mod.ghost_alpha

    def first_layer_only(*args, occluder_depth=None, **kw):
        return original(*args, occluder_depth=np.minimum(occluder_depth, first_layer + 1e-6),
                        **kw)

    monkeypatch.setattr(render_mod, "ghost_alpha", first_layer_only)
    assert check(render_cutaway(OOI, SHELLS, **cam, cutaway=cut,
                                ghosts=GhostLines(distance=G_MAX)).ghost, exp)[0] < 0.95
    monkeypatch.undo()
    # (4) the gap measured in NDC depth instead of eye units
    import refraster.cutaway.lines as lines
    monkeypatch.setattr(lines, "ndc_to_eye_depth", lambda z, proj: np.asarray(z, np.float64))
    ndc_gap = render_cutaway(OOI, SHELLS, **cam, cutaway=cut,
                             ghosts=GhostLines(distance=G_MAX))
    assert check(ndc_gap.ghost, exp)[0] < 0.95


def test_unfaded_lines_are_opaque_up_to_g_max(rendered):
    cam, fb, exp = rendered
    flat = render_cutaway(OOI, SHELLS, **cam, cutaway=Cutaway(angle=exp["angle"]),
                          ghosts=GhostLines(distance=G_MAX, fade=False))
    np.testing.assert_array_equal(flat.ghost > 0, fb.ghost > 0)
    assert set(np.unique(flat.ghost)) <= {0.0, 1.0}


def test_golden_cutaway_scene_has_ghost_lines():
    from refraster.golden import technique_scenes  # noqa: F401  (registers the scenes)
    from refraster.golden.scenes import SCENES
    scene = SCENES["cutaway_shells"].build()
    ghost = scene.buffers["ghost"]
    assert np.count_nonzero(ghost) > 100 and ghost.max() > 0.5
    assert scene.parameters["ghost_distance"] == 0.5 and scene.parameters["ghost"] == "lines"
    # ghost pixels are "may" pixels (line rasterization differs between backends)
    assert np.all(scene.may[ghost > 0])


def test_ghost_lines_lie_on_removed_depth_peeled_layers(rendered):
    """Cross-check with classic depth peeling (refraster.ldi.peel) of the secondary objects:
    every ghost pixel is within 1 px of a removed layer (z < D) inside the fade band, and many
    ghost pixels come from layers behind the first one (which the old variant could not see)."""
    from refraster.ldi import peel
    cam, fb, exp = rendered
    layers = peel(SHELLS, **cam, mode="peel")
    z = 2.0 * layers.depth.astype(np.float64) - 1.0                        # (K, H, W)
    d = 2.0 * fb.cutaway_depth.astype(np.float64) - 1.0
    gap = eye_depth_of_ndc(d, cam["proj"])[None] - eye_depth_of_ndc(z, cam["proj"])
    in_band = (layers.index >= 0) & (z < d[None]) & (gap < G_MAX + 0.05)
    any_band = in_band.any(axis=0)
    near = any_band.copy()
    near[1:] |= any_band[:-1]
    near[:-1] |= any_band[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    ghost = fb.ghost > 0
    assert np.all(near[ghost])
    deeper_only = in_band[1:].any(axis=0) & ~in_band[0]
    assert np.count_nonzero(ghost & deeper_only) > 30


def test_ghost_alpha_by_hand():
    from refraster.cutaway import ghost_alpha
    proj = rr.orthographic(-1, 1, -1, 1, 0.0, 2.0)     # eye depth = z_ndc + 1
    seg = np.array([[[-0.9, 0.05, -0.5], [0.9, 0.05, -0.5]]])   # eye depth 0.5
    cut = np.full((8, 8), -0.3)                          # D at eye depth 0.7: gap 0.2
    a = ghost_alpha(seg, view=np.eye(4), proj=proj, width=8, height=8, cutaway_ndc=cut,
                    g_max=0.4)
    want = np.zeros((8, 8))
    want[3, :] = 0.5                                     # row floor((1 − 0.05)/2 · 8) = 3
    np.testing.assert_allclose(a, want, atol=1e-6)
    flat = ghost_alpha(seg, view=np.eye(4), proj=proj, width=8, height=8, cutaway_ndc=cut,
                       g_max=0.4, fade=False)
    np.testing.assert_array_equal(flat, (want > 0).astype(np.float32))
    # beyond g_max, behind D, or behind an object of interest: nothing
    for kw in (dict(g_max=0.15), dict(cutaway_ndc=np.full((8, 8), -0.6)),
               dict(occluder_depth=np.full((8, 8), -0.9))):
        args = {"cutaway_ndc": cut, "g_max": 0.4, **kw}
        assert not ghost_alpha(seg, view=np.eye(4), proj=proj, width=8, height=8, **args).any()
    # a segment crossing D: α = 1 in the pixel where it meets D, fading toward the viewer
    slant = np.array([[[-0.95, 0.05, -0.2], [0.95, 0.05, -1.0]]])  # eye depth 0.2 → 1.0
    a = ghost_alpha(slant, view=np.eye(4), proj=proj, width=8, height=8, cutaway_ndc=cut,
                    g_max=0.4)[3]
    x_edges = np.linspace(-1, 1, 9)                      # pixel borders in x
    depth_at = 0.2 + (x_edges + 0.95) / 1.9 * 0.8        # eye depth along the segment
    far_end = np.minimum(np.clip(depth_at[1:], 0.2, 1.0), 0.7)
    want = np.where((np.clip(depth_at[:-1], 0.2, 1.0) < 0.7) & (0.7 - far_end < 0.4),
                    1 - (0.7 - far_end) / 0.4, 0.0)
    np.testing.assert_allclose(a, want, atol=1e-6)


def test_feature_segments_against_trimesh_adjacency(oracle):
    trimesh = oracle("trimesh")
    from refraster.cutaway import feature_segments
    eye = np.array([2.5, 1.7, 3.1])
    view = rr.look_at(eye, (0, 0, 0))
    proj = rr.perspective(40, 1, 1, 10)
    for mesh in (trimesh.creation.box((1.0, 2.0, 0.7)), trimesh.creation.icosphere(2, 1.0),
                 trimesh.creation.cylinder(0.5, 1.5, sections=16)):
        ours = feature_segments([(mesh.vertices, mesh.faces)], view=view, proj=proj)
        # oracle: trimesh's face adjacency; crease iff angle > 30°, silhouette iff the two faces
        # face opposite ways as seen from the eye
        pairs = mesh.face_adjacency
        edges = mesh.face_adjacency_edges
        n = mesh.face_normals
        facing = np.einsum("ij,ij->i", n, eye - mesh.vertices[mesh.faces[:, 0]]) > 0
        line = (np.degrees(mesh.face_adjacency_angles) > 30.0) | \
            (facing[pairs[:, 0]] != facing[pairs[:, 1]])
        want = {tuple(sorted(map(tuple, np.round(mesh.vertices[e], 9)))) for e in edges[line]}
        got = {tuple(sorted(map(tuple, np.round(s, 9)))) for s in ours}
        assert got == want and len(want) > 0
    # per-face vertex copies give the same lines as a shared-vertex cube
    c = trimesh.creation.box((1, 1, 1))
    split = c.vertices[c.faces].reshape(-1, 3), np.arange(len(c.faces) * 3).reshape(-1, 3)
    assert len(feature_segments([split], view=view, proj=proj)) == 12
