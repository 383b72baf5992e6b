"""The multisampled clip surface's discard and attributes per sample under a perspective
camera, against an exact float64 oracle (the perspective variant of
``tests/test_msaa_clipsurface.py`` and ``tests/test_gl_msaa_clipsurface.py``, whose clip w is 1
everywhere and so cannot tell a perspective-correct input from one divided by the wrong 1/w).

The scene: five triangles, three spanning eye depth (clip w) 1.1 … 3.8 across themselves, one
1.6 … 2.9 crossing them, one behind (near 1, far 4; the 4× clip goldens' far/near is 1.9), cut
by an oblique plane clip surface, 32×32 at 4 samples. The oracle, per sample and face: the
window-space barycentrics λ at the point the rate evaluates the fragment stage (the sample; the
pixel centre; the centroid's sample), the perspective-correct barycentrics
``b = (λ/w)/Σ(λ/w)``, the world point ``Σ b·V`` and Listing 1's ``g = n·(P − O)`` there (kept
where ``g ≥ 0``), the depth plane at the sample, and the nearest kept covering face: its
``prim_id`` and ``b``. refraster (``render_clipped`` at three rates, ``render_samples`` without
the surface) and refraster.gl (``draw_samples`` from a scene package, sample and pixel rate)
agree on every sure sample: ids equal, barycentrics within 2e-4. llvmpipe's own divide at
sample rate, ``(a/w at the sample)/(1/w at the centre)`` (docs/backends.md, "llvmpipe's divide
at sample rate"), is off by more than 0.005 on hundreds of samples here and flips the discard
of some: refraster.gl's planted ``msaa_divide_at_centre`` fails."""

from __future__ import annotations

import numpy as np
import pytest

import refraster
from conftest import gl_backend_or_skip
from refraster import RasterState
from refraster.clipsurface import render_clipped
from refraster.raster.samples import pattern, sample_points
from test_msaa_clipsurface import _plane_surface, centroid_sample

W = H = 32
#: eye-space triangles (the view is the identity's look-at: world = eye)
TRIS = np.array([
    [[-0.42, -0.45, -1.10], [0.48, -0.40, -1.20], [0.05, 1.45, -3.80]],   # floor-like, receding
    [[0.50, -0.52, -1.25], [1.55, 1.45, -3.70], [1.50, -1.55, -3.60]],    # right wall
    [[-1.65, -1.62, -3.65], [-0.30, 1.60, -3.40], [-0.50, -0.50, -1.15]],  # left wall
    [[-1.75, -1.70, -3.75], [1.75, -1.72, -3.75], [0.0, 1.75, -3.78]],    # back
    [[-0.30, 0.10, -1.60], [0.60, 0.30, -2.90], [-0.20, 0.95, -2.20]],    # crosses the floor
], np.float64)
NORMAL, ORIGIN = (0.83, -0.52, 0.21), (-0.5, 0.0, -2.1)
RATES = {"sample": "sample", "center": "center", "centroid": "centroid"}


def _camera():
    view = refraster.camera.look_at([0.0, 0.0, 0.0], [0.0, 0.0, -1.0])
    proj = refraster.camera.perspective(50.0, 1.0, 1.0, 4.0)
    return view, proj


def _mesh():
    v = TRIS.reshape(-1, 3).astype(np.float32)
    return v, np.arange(len(v)).reshape(-1, 3)


def oracle(state, rate, *, defect=False, discard=True):
    """Per sample ``(prim (H, W, S), bary (H, W, S, 3), sure (H, W, S))`` in float64, rows top
    first. ``rate``: where the fragment stage evaluates (``"sample"``, ``"center"``,
    ``"centroid"``). ``defect``: llvmpipe's divide at sample rate instead of the exact one —
    ``(λ/w)`` at the evaluation point over ``Σ λ/w`` at the pixel centre. ``sure``: every
    covering face's sample is 0.01 px inside its edges or outside them, no keep decision within
    1e-4 of ``g = 0`` and no two kept depths within 1e-5. ``discard=False``: nothing discarded
    (``render_samples``' frame)."""
    v, f = _mesh()
    view, proj = _camera()
    clip = np.c_[v.astype(np.float64), np.ones(len(v))] @ (proj @ view).T
    w = clip[:, 3]
    xw = (clip[:, 0] / w * 0.5 + 0.5) * W
    yw = (clip[:, 1] / w * 0.5 + 0.5) * H
    zw = clip[:, 2] / w * 0.5 + 0.5
    pts = sample_points(state)                                  # (S, 2) px, y down
    s = len(pts)
    col, row = np.meshgrid(np.arange(W), np.arange(H))         # row: picture, top first
    SX = col[..., None] + pts[:, 0]
    SY = H - (row[..., None] + pts[:, 1])                       # window y, up
    CX = col[..., None] + 0.5 + 0.0 * SX
    CY = H - row[..., None] - 0.5 + 0.0 * SY
    n = np.asarray(NORMAL, np.float64) / np.linalg.norm(NORMAL)
    best = np.full((H, W, s), np.inf)
    prim = np.full((H, W, s), -1)
    bary = np.zeros((H, W, s, 3))
    sure = np.ones((H, W, s), bool)
    kept_z = []
    for i, ids in enumerate(f):
        x, y = xw[ids], yw[ids]
        area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])

        def lam(px, py):
            l1 = ((px - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (py - y[0])) / area
            l2 = ((x[1] - x[0]) * (py - y[0]) - (px - x[0]) * (y[1] - y[0])) / area
            return np.stack([1.0 - l1 - l2, l1, l2], -1)

        ls = lam(SX, SY)
        # signed distance (px) of the sample to each edge, inside positive
        dist = []
        for k in range(3):
            p, q = (k + 1) % 3, (k + 2) % 3
            length = np.hypot(x[q] - x[p], y[q] - y[p])
            dist.append(ls[..., k] * abs(area) / length)
        dist = np.stack(dist, -1)
        cov = (dist > 0).all(-1)
        sure &= ~(np.abs(dist) < 0.01).any(-1) | ~((dist > -0.01).all(-1))
        if rate == "sample":
            ex, ey = SX, SY
        elif rate == "center":
            ex, ey = CX, CY
        else:                                   # the covered sample nearest the centre
            pick = centroid_sample(cov, (pts[:, 0] - 0.5) ** 2 + (pts[:, 1] - 0.5) ** 2)
            at = np.maximum(pick, 0)
            ex = np.where(pick >= 0, col + pts[at, 0], col + 0.5)[..., None] + 0.0 * SX
            ey = np.where(pick >= 0, H - row - pts[at, 1], H - row - 0.5)[..., None] + 0.0 * SY
        q = lam(ex, ey) / w[ids]
        total = (lam(CX, CY) / w[ids]).sum(-1) if defect else q.sum(-1)
        b = q / total[..., None]
        P = b @ v[ids].astype(np.float64)
        g = (P - np.asarray(ORIGIN)) @ n
        z = ls @ zw[ids]
        keep = g >= 0 if discard else np.ones_like(cov)
        if discard:
            sure &= ~(cov & (np.abs(g) < 1e-4))
        kept_z.append(np.where(cov & keep, z, np.inf))
        win = cov & keep & (z < best)
        best = np.where(win, z, best)
        prim = np.where(win, i, prim)
        bary = np.where(win[..., None], b, bary)
    d = np.sort(np.stack(kept_z), axis=0)
    with np.errstate(invalid="ignore"):
        sure &= ~(np.isfinite(d[0]) & (d[1] - d[0] < 1e-5))
    return prim, bary, sure


def compare(prim, bary, state, rate, *, tol=2e-4, discard=True):
    """``(samples compared, ids that differ, barycentrics off by more than tol)`` against the
    exact oracle (tol relative where the pixel centre's value is extrapolated beyond ±1);
    asserts that 95 % of the samples are sure."""
    want, wbary, sure = oracle(state, rate, discard=discard)
    assert sure.mean() > 0.95
    ids = int(((prim != want) & sure).sum())
    same = sure & (prim == want) & (want >= 0)
    scale = np.maximum(1.0, np.abs(wbary).max(-1))     # extrapolated far outside the face
    off = int((np.abs(bary - wbary).max(-1) > tol * scale)[same].sum())
    return int(sure.sum()), ids, off


@pytest.fixture(scope="module")
def defect_visible():
    """The scene sees llvmpipe's divide: at sample rate it moves the barycentrics by more than
    0.005 on 100+ sure samples and flips the discard (the id) of some."""
    st = RasterState(samples=4, sample_locations="gl_llvmpipe", interpolation="sample")
    prim, bary, sure = oracle(st, "sample")
    dprim, dbary, dsure = oracle(st, "sample", defect=True)
    both = sure & dsure & (prim == dprim) & (prim >= 0)
    moved = int((np.abs(bary - dbary).max(-1) > 5e-3)[both].sum())
    flipped = int(((prim != dprim) & sure & dsure).sum())
    assert moved >= 100 and flipped >= 3, (moved, flipped)
    return moved, flipped


def _ours(state):
    v, f = _mesh()
    view, proj = _camera()
    cs, _ = _plane_surface(NORMAL, ORIGIN)
    fb = render_clipped((v, f), cs, view=view, proj=proj, width=W, height=H, caps=None,
                        raster=state)
    return fb.prim_id, fb.barycentric


@pytest.mark.parametrize("interpolation", ["sample", "center", "centroid"])
@pytest.mark.parametrize("locations", ["standard", "gl_llvmpipe"])
def test_refraster_per_sample_perspective_matches_the_exact_oracle(interpolation, locations,
                                                                   defect_visible):
    st = RasterState(samples=4, sample_locations=locations, interpolation=interpolation)
    prim, bary = _ours(st)
    n, ids, off = compare(prim, bary, st, RATES[interpolation])
    assert ids == 0 and off == 0, (f"{interpolation}: of {n} sure samples {ids} ids and {off} "
                                   "barycentrics differ from the exact perspective oracle")


@pytest.mark.parametrize("interpolation", ["sample", "center", "centroid"])
def test_render_samples_perspective_matches_the_exact_oracle(interpolation, defect_visible):
    """The multisampled G-buffer's own pass (``render_samples``, no clip surface): the
    perspective variant of ``tests/test_msaa.py::test_interpolation_points`` (w = 1 there)."""
    v, f = _mesh()
    view, proj = _camera()
    st = RasterState(samples=4, interpolation=interpolation)
    sf = refraster.render_samples((v, f), view=view, proj=proj, width=W, height=H, raster=st)
    n, ids, off = compare(sf.prim_id, sf.barycentric, st, RATES[interpolation],
                            discard=False)
    assert ids == 0 and off == 0, (f"{interpolation}: of {n} sure samples {ids} ids and {off} "
                                   "barycentrics differ from the exact perspective oracle")


def test_the_oracle_tells_the_rates_apart(defect_visible):
    """Each rate's frame fails the other rate's oracle (ids and barycentrics): a sample-rate
    path that evaluated at the centre, or the reverse, fails the test above."""
    st = RasterState(samples=4, sample_locations="gl_llvmpipe", interpolation="sample")
    for ours, other in (("sample", "center"), ("center", "sample"), ("centroid", "sample")):
        prim, bary = _ours(st.replace(interpolation=ours))
        n, ids, off = compare(prim, bary, st.replace(interpolation=other), other)
        assert ids >= 5 and off >= 100, (ours, other, n, ids, off)


# --- refraster.gl from a scene package --------------------------------------------------------

def _package(tmp, interpolation):
    from refraster.clipsurface import offsetmaps as om
    from refraster.golden.io.package import export_package
    from refraster.camera import Camera
    from refraster.golden.scenes import Draw, GoldenScene, prepare_draws, raster_state
    raster = {"samples": 4, "sample_locations": "gl_llvmpipe", "interpolation": interpolation}
    cs, _ = _plane_surface(NORMAL, ORIGIN)
    view, proj = _camera()
    surface = {"origin": [float(c) for c in cs.origin], "u": [float(c) for c in cs.u],
               "v": [float(c) for c in cs.v], "scale": [float(c) for c in cs.scale],
               "wrap": "repeat", "enabled": True, "offset_map": "offset_map"}
    scene = GoldenScene(technique="clipsurface", camera=Camera(view, proj, W, H),
                        draws=prepare_draws([Draw("tris", _mesh())]), buffers={},
                        parameters={"surfaces": [surface], "caps": False, "cap_mode": "mesh",
                                    "evaluation_space": "world",
                                    "sample_pattern": {"samples": 4, "positions": [
                                        [int(x), int(y)] for x, y in
                                        pattern(RasterState(**raster))]}},
                        maps={"offset_map": np.asarray(om.constant(4, 0.0), np.float32)},
                        raster=raster, geometry=False)
    pkg = tmp / f"persp_{interpolation}"
    export_package(pkg, f"persp_{interpolation}", scene, raster_state(raster))
    return pkg


def _gl(pkg, faults=()):
    from refraster.gl.driver import Backend
    gl_backend_or_skip().release()
    with Backend(faults=faults) as gl:
        out = gl.render(pkg)
    prim = np.stack([out[f"sample{s}_prim_id"] for s in range(4)], -1)
    bary = np.stack([out[f"sample{s}_barycentric"] for s in range(4)], -2)
    return prim, bary


@pytest.mark.parametrize("interpolation", ["sample", "center"])
def test_gl_per_sample_perspective_matches_the_exact_oracle(tmp_path, interpolation,
                                                            defect_visible):
    st = RasterState(samples=4, sample_locations="gl_llvmpipe", interpolation=interpolation)
    prim, bary = _gl(_package(tmp_path, interpolation))
    n, ids, off = compare(prim, bary, st, RATES[interpolation])
    assert ids == 0 and off == 0, (f"{interpolation}: of {n} sure samples {ids} ids and {off} "
                                   "barycentrics differ from the exact perspective oracle")


def test_gl_divide_at_centre_fails_the_perspective_oracle(tmp_path, defect_visible):
    """The planted ``msaa_divide_at_centre`` (llvmpipe's own divide of the sample-rate inputs)
    fails: ids at the cut and barycentrics, against the exact oracle; it is the oracle's own
    model of the defect within the tolerance."""
    st = RasterState(samples=4, sample_locations="gl_llvmpipe", interpolation="sample")
    prim, bary = _gl(_package(tmp_path, "sample"), faults=["msaa_divide_at_centre"])
    n, ids, off = compare(prim, bary, st, "sample")
    assert ids >= 1 and off >= 100, (n, ids, off)
    dprim, dbary, dsure = oracle(st, "sample", defect=True)
    same = dsure & (prim == dprim) & (dprim >= 0)
    assert ((prim != dprim) & dsure).sum() == 0
    assert np.abs(bary - dbary).max(-1)[same].max() < 2e-4
