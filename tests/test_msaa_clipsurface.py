"""Clip surfaces, caps and depth peeling at ``samples > 1`` (issue 44 item 1): the per-sample
fragment stream against render_samples, the clip surface's discard per sample (pixel rate at
the centre or centroid, sample rate at each sample) against a float64 brute-force oracle, caps
against an analytic box, and each sample's own peel layers against brute force
(``docs/multisample.md``, "Fragment stages per sample")."""

from __future__ import annotations

import numpy as np
import pytest

import refraster
from refraster import RasterState
from refraster.clipsurface import (Caps, ClippedSampleFramebuffer, ClipSurface,
                                   render_clipped)
from refraster.clipsurface import offsetmaps as om
from refraster.framebuffer import Framebuffer
from refraster.multisample import draw_samples, sample_image
from refraster.raster._sample_tables import STANDARD
from test_msaa import _soup, _window

EYE = np.eye(4)
W, H = 23, 17


# ------------------------------------------------------------ the stream is render_samples'

@pytest.mark.parametrize("interpolation", ["center", "centroid", "sample"])
@pytest.mark.parametrize("samples", [2, 4, 8, 16])
def test_resolved_sample_stream_is_render_samples(samples, interpolation):
    v, f = _soup(samples, 30, W, H, grid=samples == 4)
    st = RasterState(samples=samples, interpolation=interpolation)
    sf = refraster.render_samples((v, f), view=EYE, proj=EYE, width=W, height=H, raster=st)
    frags = draw_samples((v, f), view=EYE, proj=EYE, width=W, height=H, raster=st)
    one = sample_image(st)
    fb = Framebuffer.from_fragments(frags, refraster.resolve(frags, raster=one), raster=one)
    for k in ("depth", "prim_id", "front_facing", "barycentric", "normal", "eye_depth"):
        np.testing.assert_array_equal(getattr(fb, k).reshape(getattr(sf, k).shape),
                                      getattr(sf, k), err_msg=k)


def test_shading_rate_names_the_interpolation():
    assert RasterState().shading_rate == "pixel"
    assert RasterState(samples=4, interpolation="centroid").shading_rate == "pixel"
    assert RasterState(samples=4, interpolation="sample").shading_rate == "sample"


# ------------------------------------------------------- the discard per sample, brute force

def _plane_surface(normal, origin):
    n = np.asarray(normal, np.float64)
    n /= np.linalg.norm(n)
    u = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return ClipSurface(origin, u, v, (1, 1, 0), om.constant(4, 0.0)), n


def centroid_sample(cov, d2):
    """Per pixel of ``cov (H, W, S)`` the covered sample nearest the centre (``d2 (S,)``: each
    sample's squared distance to it; the lowest index among equals), −1 where the face covers
    every sample or none (the centroid point is then the centre)."""
    pick = np.full(cov.shape[:2], -1)
    for t in sorted(range(cov.shape[2]), key=lambda t: (d2[t], t))[::-1]:
        pick = np.where(cov[:, :, t], t, pick)
    return np.where(cov.all(axis=2), -1, pick)


def _oracle(v, faces, positions, normal, origin, rate, rule="llvmpipe"):
    """Per-sample face of the clipped frame, brute force in float64 (identity matrices: clip
    = world, w = 1). Each face's coverage of each sample: exact integer edge functions of the
    snapped vertices with the fill rule (as ``test_msaa.twin``); its keep decision: ``g ≥ 0``
    at the point where ``rate`` evaluates it — the sample (``"sample"``), the pixel centre
    (``"center"``), or the centre when the face covers every sample of the pixel, else its
    covered sample nearest the centre, lowest index first (``"centroid"``) — the world point
    being the face's plane there (extrapolated); then the nearest kept covering face.
    Returns ``prim (H, W, S)`` (−1 background) and ``sure (H, W, S)``: no keep decision within
    1e-5 of ``g = 0`` and no two candidate depths within 1e-5."""
    xw, yw, zw, X, Y = _window(v, W, H)
    pos = np.asarray(positions, np.int64)
    s = len(pos)
    px, py = np.meshgrid(np.arange(W), np.arange(H))
    SX = (px[..., None] << 8) + (pos[:, 0] - 8) * 16
    SY = (py[..., None] << 8) + (8 - pos[:, 1]) * 16
    FX = px[..., None] + 0.5 + (pos[:, 0] - 8) / 16.0
    FY = py[..., None] + 0.5 + (8 - pos[:, 1]) / 16.0
    CX, CY = px[..., None] + 0.5 + 0.0 * FX, py[..., None] + 0.5 + 0.0 * FY
    n = np.asarray(normal, np.float64)
    n /= np.linalg.norm(n)
    best = np.full((H, W, s), np.inf)
    prim = np.full((H, W, s), -1)
    sure = np.ones((H, W, s), bool)
    depths = []
    for i, (a, b, c) in enumerate(faces):
        ids = [a, b, c]
        area = (X[b] - X[a]) * (Y[c] - Y[a]) - (X[c] - X[a]) * (Y[b] - Y[a])
        if area == 0:
            continue
        if area < 0:
            ids = [a, c, b]
        cov = np.ones((H, W, s), bool)
        for k in range(3):
            p, q = ids[(k + 1) % 3], ids[(k + 2) % 3]
            dx, dy = X[q] - X[p], Y[q] - Y[p]
            e = dx * (SY - Y[p]) - dy * (SX - X[p])
            owns = dy < 0 or (dy == 0 and (dx > 0 if rule == "llvmpipe" else dx < 0))
            cov &= (e > 0) | ((e == 0) & owns)
        x0, y0, x1, y1, x2, y2 = xw[a], yw[a], xw[b], yw[b], xw[c], yw[c]
        den = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)

        def world(fx, fy):
            l1 = ((fx - x0) * (y2 - y0) - (x2 - x0) * (fy - y0)) / den
            l2 = ((x1 - x0) * (fy - y0) - (fx - x0) * (y1 - y0)) / den
            l0 = 1.0 - l1 - l2
            p = [l0 * v[a, j] + l1 * v[b, j] + l2 * v[c, j] for j in range(3)]
            return np.stack(np.broadcast_arrays(*p), axis=-1), zw[a] + l1 * (zw[b] - zw[a]) \
                + l2 * (zw[c] - zw[a])

        if rate == "sample":
            ex, ey = FX, FY
        elif rate == "center":
            ex, ey = CX, CY
        else:
            pick = centroid_sample(cov, (pos[:, 0] - 8) ** 2 + (pos[:, 1] - 8) ** 2)
            at = np.maximum(pick, 0)
            ex = np.where(pick >= 0, px + 0.5 + (pos[at, 0] - 8) / 16.0, px + 0.5)
            ey = np.where(pick >= 0, py + 0.5 + (8 - pos[at, 1]) / 16.0, py + 0.5)
            ex, ey = ex[..., None] + 0.0 * FX, ey[..., None] + 0.0 * FY
        P, _ = world(ex, ey)
        g = (P - np.asarray(origin)) @ n
        _, z = world(FX, FY)
        z = np.clip(z, 0.0, 1.0)
        keep = g >= 0
        sure &= ~(cov & (np.abs(g) < 1e-5))
        depths.append(np.where(cov & keep, z, np.inf))
        win = cov & keep & (z.astype(np.float32) < best.astype(np.float32))
        best = np.where(win, z, best)
        prim = np.where(win, i, prim)
    d = np.sort(np.stack(depths), axis=0)
    if len(d) > 1:
        with np.errstate(invalid="ignore"):   # inf − inf where nothing is kept
            sure &= ~(np.isfinite(d[0]) & (d[1] - d[0] < 1e-5))
    flip = (slice(None, None, -1),)
    return prim[flip], sure[flip]


def _layers_scene():
    """A front triangle that crosses pixels with its edges, two large planes behind it."""
    v = np.array([[-0.93, -0.81, -0.6], [0.71, -0.52, -0.2], [-0.22, 0.87, -0.4],
                  [-1.0, -1.0, 0.0], [3.0, -1.0, 0.2], [-1.0, 3.0, 0.1],
                  [-1.0, -1.0, 0.6], [3.0, -1.0, 0.5], [-1.0, 3.0, 0.7]], np.float32)
    return v, np.arange(9).reshape(3, 3)


NORMAL, ORIGIN = (0.83, -0.52, 0.21), (0.031, -0.017, 0.0)


def _clipped(v, f, state):
    cs, _ = _plane_surface(NORMAL, ORIGIN)
    return render_clipped((v, f), cs, view=EYE, proj=EYE, width=W, height=H, caps=None,
                          raster=state)


@pytest.mark.parametrize("samples", [4, 8])
@pytest.mark.parametrize("interpolation", ["center", "centroid", "sample"])
def test_discard_per_sample_matches_the_float64_oracle(samples, interpolation):
    v, f = _layers_scene()
    st = RasterState(samples=samples, interpolation=interpolation)
    fb = _clipped(v, f, st)
    assert isinstance(fb, ClippedSampleFramebuffer) and fb.depth.shape == (H, W, samples)
    rate = {"center": "center", "centroid": "centroid", "sample": "sample"}[interpolation]
    want, sure = _oracle(v, f, STANDARD[samples], NORMAL, ORIGIN, rate)
    assert sure.mean() > 0.97
    bad = (fb.prim_id != want) & sure
    assert not bad.any(), (f"{interpolation}: {int(bad.sum())} of {int(sure.sum())} samples "
                           f"differ from the oracle, first at {np.argwhere(bad)[:3].tolist()}")
    # the plane crosses pixels: some pixel's samples are split between kept and discarded
    front = fb.prim_id == 0
    split = front.any(axis=2) & ~front.all(axis=2)
    assert split.sum() >= 10


@pytest.mark.parametrize("samples", [4, 8])
def test_pixel_rate_and_sample_rate_are_different_pictures(samples):
    """The oracle tells the rates apart: each rate's frame disagrees with the other rate's
    oracle on sure samples (so discarding at pixel rate where sample rate is declared, or
    the other way round, fails the test above)."""
    v, f = _layers_scene()
    for ours, other in (("sample", "center"), ("center", "sample"), ("centroid", "sample")):
        fb = _clipped(v, f, RasterState(samples=samples, interpolation=ours))
        want, sure = _oracle(v, f, STANDARD[samples], NORMAL, ORIGIN, other)
        assert ((fb.prim_id != want) & sure).sum() >= 5, (ours, other)


def test_unclipped_and_single_sample_frames_are_the_known_ones():
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    cs = ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.3), om.perlin_noise(16))
    kw = dict(view=refraster.camera.look_at([1.5, 1.2, 2.2], [0, 0, 0]),
              proj=refraster.camera.perspective(35, 4 / 3, 0.5, 10), width=40, height=30)
    for interp in ("center", "centroid", "sample"):
        st = RasterState(samples=4, interpolation=interp)
        off = render_clipped(box, cs.replace(enabled=False), **kw, raster=st)
        plain = refraster.render_samples(box, **kw, raster=st)
        for k in ("depth", "prim_id", "barycentric", "normal", "color"):
            np.testing.assert_array_equal(getattr(off, k), getattr(plain, k), err_msg=k)
    # one sample at the centre through the sample stream: the single-sample (fused) frame
    caps = Caps(style="hatch", vds_resolution=256)
    one = render_clipped(box, cs, **kw, caps=caps,
                         raster=RasterState(sample_locations=((8, 8),)))
    ref = render_clipped(box, cs, **kw, caps=caps)
    for k in ("depth", "prim_id", "object_id", "barycentric", "normal", "color", "cap_mask"):
        np.testing.assert_array_equal(getattr(one, k)[:, :, 0], getattr(ref, k), err_msg=k)
    np.testing.assert_array_equal(one.cap_points, ref.cap_points)


def test_exact_caps_are_refused_at_samples():
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    cs = ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.3), om.constant(4, 0.5))
    with pytest.raises(ValueError, match=r"^caps.mode must be 'mesh' at raster.samples=4"):
        render_clipped(box, cs, view=EYE, proj=EYE, width=8, height=8,
                       caps=Caps(mode="exact"), raster=RasterState(samples=4))


# --------------------------------------------------------------- caps against an analytic box

def _box_oracle(kw, st, z_cut, rate):
    """Per sample, which of the box [−½, ½]³ cut at z = z_cut (kept below) and its cap the
    sample shows, from rays in float64: 0 solid, 1 cap, −1 nothing; ``sure``: the sample's
    and its evaluation point's hits are 2e-3 away from every edge of the decision (box
    edges, the cut line, the cap's rim)."""
    s = st.samples
    inv = np.linalg.inv(kw["proj"] @ kw["view"])
    w, h = kw["width"], kw["height"]
    pos = np.asarray(refraster.raster.samples.sample_points(st))      # (S, 2) px, y down

    def rays(x, y):   # picture coordinates, y down
        ndc = np.stack([2 * x / w - 1, 1 - 2 * y / h], -1)
        a = np.concatenate([ndc, -np.ones(ndc.shape[:-1] + (1,)), np.ones(ndc.shape[:-1] + (1,))],
                           -1) @ inv.T
        b = np.concatenate([ndc, np.ones(ndc.shape[:-1] + (1,)), np.ones(ndc.shape[:-1] + (1,))],
                           -1) @ inv.T
        a, b = a[..., :3] / a[..., 3:], b[..., :3] / b[..., 3:]
        return a, b - a

    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    sx = cols[..., None] + pos[:, 0]
    sy = rows[..., None] + pos[:, 1]
    o, d = rays(sx, sy)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (-0.5 - o) / d
        t1 = (0.5 - o) / d
    tin = np.minimum(t0, t1).max(-1)
    tout = np.maximum(t0, t1).min(-1)
    hit_box = tin < tout
    if rate == "sample":
        co, cd = o, d
    else:
        co, cd = rays(cols[..., None] + 0.5 + 0 * pos[:, 0], rows[..., None] + 0.5 + 0 * pos[:, 1])

    def face_at_evaluation(t_face, nearest, sign):
        """z where the evaluation ray meets the plane of the face the sample ray enters
        (``sign`` −1) or leaves (+1) through: the face fragment's keep decision."""
        axis = np.argmax(nearest == t_face[..., None], -1)
        plane = np.take_along_axis(np.where(d > 0, sign * 0.5, -sign * 0.5), axis[..., None],
                                   -1)[..., 0]
        oc = np.take_along_axis(co, axis[..., None], -1)[..., 0]
        dc = np.take_along_axis(cd, axis[..., None], -1)[..., 0]
        return co[..., 2] + (plane - oc) / dc * cd[..., 2]

    # the box's entry (front) and exit (back) faces: kept where the evaluation point on their
    # plane lies below the cut
    z_in = face_at_evaluation(tin, np.minimum(t0, t1), -1)
    z_out = face_at_evaluation(tout, np.maximum(t0, t1), 1)
    # the cap plane z = z_cut: drawn wherever the sample meets it near the box (the cap grid
    # spans the box's bounds), kept where its evaluation point is inside the box
    tz = (z_cut - o[..., 2]) / d[..., 2]
    pz = o + tz[..., None] * d
    cz = co + ((z_cut - co[..., 2]) / cd[..., 2])[..., None] * cd
    cap = np.all(np.abs(cz[..., :2]) < 0.5, -1) & (np.abs(pz[..., :2]).max(-1) < 0.75)
    t_cand = np.stack([np.where(hit_box & (z_in < z_cut), tin, np.inf),
                       np.where(hit_box & (z_out < z_cut), tout, np.inf),
                       np.where(cap, tz, np.inf)], -1)
    near = np.argmin(t_cand, -1)
    out = np.where(np.isfinite(t_cand.min(-1)), np.array([0, 0, 1])[near], -1)
    m = 2e-3
    sure = np.abs(np.abs(cz[..., :2]).max(-1) - 0.5) > m
    sure &= np.abs(np.abs(pz[..., :2]).max(-1) - 0.5) > m
    for t, z in ((tin, z_in), (tout, z_out)):
        p = o + t[..., None] * d
        edge = np.sort(np.abs(np.abs(p) - 0.5), -1)[..., 1]    # distance to the face's rim
        sure &= ~hit_box | ((edge > m) & (np.abs(z - z_cut) > m))
    return out, sure


@pytest.mark.parametrize("interpolation", ["center", "sample"])
def test_caps_per_sample_against_the_analytic_box(interpolation):
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    z_cut = 0.13
    cs = ClipSurface([0, 0, z_cut], [1.5, 0, 0], [0, -1.5, 0], (1, 1, 0), om.constant(4, 0.0))
    assert np.allclose(cs.normal, [0, 0, -1])
    kw = dict(view=refraster.camera.look_at([1.3, 1.0, 2.4], [0, 0, 0]),
              proj=refraster.camera.perspective(40, 4 / 3, 0.5, 10), width=48, height=36)
    st = RasterState(samples=4, interpolation=interpolation)
    fb = render_clipped(box, cs, **kw, caps=Caps(vds_resolution=512), raster=st)
    got = np.where(fb.prim_id < 0, -1, np.where(fb.cap_mask, 1, 0))
    want, sure = _box_oracle(kw, st, z_cut, "sample" if interpolation == "sample" else "center")
    assert sure.mean() > 0.9 and (want == 1).sum() > 300
    bad = (got != want) & sure
    assert not bad.any(), (f"{int(bad.sum())} of {int(sure.sum())} samples differ, first at "
                           f"{np.argwhere(bad)[:3].tolist()}")
    # cap samples lie on the cut, inside the box
    np.testing.assert_allclose(fb.cap_points[:, 2], z_cut, atol=1e-5)
    assert (np.abs(fb.cap_points[:, :2]) < 0.5 + 2e-3).all()


# ------------------------------------------------------------ each sample peels its own layers

def _peel_oracle(v, faces, positions, mode):
    """Per-sample layers by brute force: every face covering the sample (exact integer edge
    functions), its float64 depth plane at the sample, sorted front to back (ties in draw
    order); ``"peel"`` keeps the first of each run of equal float32 depths below 1."""
    xw, yw, zw, X, Y = _window(v, W, H)
    pos = np.asarray(positions, np.int64)
    s = len(pos)
    px, py = np.meshgrid(np.arange(W), np.arange(H))
    SX = (px[..., None] << 8) + (pos[:, 0] - 8) * 16
    SY = (py[..., None] << 8) + (8 - pos[:, 1]) * 16
    FX = px[..., None] + 0.5 + (pos[:, 0] - 8) / 16.0
    FY = py[..., None] + 0.5 + (8 - pos[:, 1]) / 16.0
    frags = [[[[] for _ in range(s)] for _ in range(W)] for _ in range(H)]
    for i, (a, b, c) in enumerate(faces):
        ids = [a, b, c]
        area = (X[b] - X[a]) * (Y[c] - Y[a]) - (X[c] - X[a]) * (Y[b] - Y[a])
        if area == 0:
            continue
        if area < 0:
            ids = [a, c, b]
        cov = np.ones((H, W, s), bool)
        for k in range(3):
            p, q = ids[(k + 1) % 3], ids[(k + 2) % 3]
            dx, dy = X[q] - X[p], Y[q] - Y[p]
            e = dx * (SY - Y[p]) - dy * (SX - X[p])
            owns = dy < 0 or (dy == 0 and dx > 0)
            cov &= (e > 0) | ((e == 0) & owns)
        x0, y0, x1, y1, x2, y2 = xw[a], yw[a], xw[b], yw[b], xw[c], yw[c]
        den = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        l1 = ((FX - x0) * (y2 - y0) - (x2 - x0) * (FY - y0)) / den
        l2 = ((x1 - x0) * (FY - y0) - (FX - x0) * (y1 - y0)) / den
        z = np.clip(zw[a] + l1 * (zw[b] - zw[a]) + l2 * (zw[c] - zw[a]), 0.0, 1.0)
        for r, cc, t in np.argwhere(cov):
            frags[H - 1 - r][cc][t].append((float(z[r, cc, t]), i))
    return frags


def _layers_of(frag_list, mode):
    out = sorted(frag_list, key=lambda zi: zi[0])     # stable: ties in draw order
    if mode == "all":
        return out
    kept = []
    for z, i in out:
        if np.float32(z) >= 1.0:
            continue
        if kept and np.float32(z) == np.float32(kept[-1][0]):
            continue
        kept.append((z, i))
    return kept


def _check_layers(lay, oracle, mode):
    """``lay`` (K, H, W, S) against the oracle; returns the number of samples compared and
    of those that differ (samples whose candidate depths are within 1e-5 are not compared)."""
    compared = differ = 0
    for r in range(H):
        for c in range(W):
            for s in range(lay.depth.shape[3]):
                want = _layers_of(oracle[r][c][s], mode)
                zs = [z for z, _ in want]
                if any(b - a < 1e-5 for a, b in zip(zs, zs[1:])):
                    continue
                compared += 1
                n = int(lay.count[r, c, s])
                got = [(float(lay.depth[k, r, c, s]), int(lay.prim_id[k, r, c, s]))
                       for k in range(n)]
                if len(got) != len(want) or any(
                        gi != wi or abs(gz - wz) > 2e-7 for (gz, gi), (wz, wi) in zip(got, want)):
                    differ += 1
    return compared, differ


@pytest.mark.parametrize("mode", ["peel", "all"])
@pytest.mark.parametrize("samples", [4, 8])
def test_each_sample_peels_its_own_layers(samples, mode):
    v, f = _soup(11 + samples, 25, W, H)
    oracle = _peel_oracle(v, f, STANDARD[samples], mode)
    lay = refraster.ldi.peel((v, f), view=EYE, proj=EYE, width=W, height=H, mode=mode,
                             raster=RasterState(samples=samples))
    assert lay.depth.shape[1:] == (H, W, samples) and lay.count.shape == (H, W, samples)
    compared, differ = _check_layers(lay, oracle, mode)
    assert compared > 0.95 * H * W * samples
    assert differ == 0, f"{differ} of {compared} samples' layers differ from brute force"
    # layers differ between the samples of a pixel (else the check above could not see a peel
    # that shares one layer index across a pixel's samples)
    assert (lay.prim_id != lay.prim_id[..., :1]).any(axis=(0, 3)).sum() > 20


def test_a_peel_sharing_one_layer_index_across_samples_fails():
    """The check of each sample's own layers fails a peel whose layer k is the pixel's k-th
    fragment (its triangle's depth order at the centre) written to the samples it covers."""
    import dataclasses
    v, f = _soup(15, 25, W, H)
    st = RasterState(samples=4)
    oracle = _peel_oracle(v, f, STANDARD[4], "all")
    lay = refraster.ldi.peel((v, f), view=EYE, proj=EYE, width=W, height=H, mode="all",
                             raster=st)
    # per pixel, each triangle once, ordered by its nearest sample's depth; every sample of
    # the pixel gets that triangle's layer index (empty where it does not cover the sample)
    k, h, w, s = lay.depth.shape
    shared = dataclasses.replace(lay, depth=np.full((k * s, h, w, s), 1.0, np.float32),
                                 prim_id=np.full((k * s, h, w, s), -1, np.int32),
                                 count=np.zeros((h, w, s), np.int32))
    for r in range(h):
        for c in range(w):
            tris = {}
            for t in range(s):
                for j in range(int(lay.count[r, c, t])):
                    p = int(lay.prim_id[j, r, c, t])
                    tris.setdefault(p, {})[t] = float(lay.depth[j, r, c, t])
            order = sorted(tris, key=lambda p: min(tris[p].values()))
            for j, p in enumerate(order):
                for t, z in tris[p].items():
                    shared.depth[j, r, c, t] = z
                    shared.prim_id[j, r, c, t] = p
            shared.count[r, c, :] = len(order)
    compared, differ = _check_layers(shared, oracle, "all")
    assert differ > 50, (differ, compared)


def test_peel_refusals_and_one_sample():
    v, f = _soup(3, 10, W, H)
    one = refraster.ldi.peel((v, f), view=EYE, proj=EYE, width=W, height=H)
    centre = refraster.ldi.peel((v, f), view=EYE, proj=EYE, width=W, height=H,
                                raster=RasterState(sample_locations=((8, 8),)))
    np.testing.assert_array_equal(centre.depth[..., 0], one.depth)
    np.testing.assert_array_equal(centre.prim_id[..., 0], one.prim_id)
    with pytest.raises(ValueError, match="^raster.depth_func must be one of"):
        refraster.ldi.peel((v, f), view=EYE, proj=EYE, width=W, height=H,
                           raster=RasterState(samples=4, depth_func="always"))
