"""Allowances of the cutaway depth D ("Goldens with teeth (2)", item 4).

D (MATH.md §4.1) is ``max(−1, max_s [z(s) − m(s)·‖x − s‖])`` over the seeds s — the pixels of the
rear hulls of the objects of interest (rendered with depth test ``greater``, clear 0) — with
``m(s)`` from θ, perspective compensation (``m = −(P₂₂ + z)/tan θ_e``) and edge compression
(θ_e from the pixel's position only). Every flooding variant computes the maximum over a subset
of the seeds it visits, so no variant exceeds the exact maximum; the exact D is increasing in each
seed's depth (``∂/∂z [z − m(z)·d] = 1 + d/tan θ_e > 0``; orthographic: m constant) and in the set
of seeds.

What a conformant GPU may change in the seeds is plain rendering's: which faces cover a pixel
centre (the edge ε) and each face's depth there (the ε-square and the float32 slack). The
golden takes the per-pixel faces whose ε-dilated footprint covers the centre with their depth
intervals (:func:`refraster.golden.layers.covering_entries`, hidden faces included) and forms
two seed images at the cutaway resolution:

* **largest**: every pixel some face may cover, at the largest depth any of them may show;
* **smallest**: only pixels some face surely covers (ε to spare, not a sliver), at the least
  depth the farthest surely-covering face may show (the rear hull is at least that far).

Then ``D_hi = exact(largest) + slack`` (no variant, no seed set exceeds it) and
``D_lo = min over the accepted variants v of flood_v(smallest), flood_v(largest) − slack``;
jump flooding is not monotone in its seeds (a new seed can displace a better one on the way),
so the lower bound takes both seed images and refraster's own rear hull (measured: ``1+jfa``
over refraster's own seeds falls 1.7e−5 below the floods of the other two at one pixel of
``cutaway_shells``). This lower bound is the one part not proven for every seed image a GPU may
make: a rear hull unlike all three could, where jump flooding is trapped, fall lower at isolated
pixels (none of refraster's 4/8-bit, fill-rule and float64 rear hulls does, for any accepted
variant). ``slack`` covers float32 evaluation of
``z − m·‖x − s‖`` (``16·2⁻²⁴·(1 + |z| + m·‖x − s‖)`` ≤ 16·2⁻²⁴·(2 + m_max·diag)) and of the
conversion to window depth. The scene states the variants it accepts (``accepted_variants``:
its own and the exact maximum, and those at least as good as its own).
"""

from __future__ import annotations

import numpy as np

__all__ = ["cutaway_bounds"]

F32 = 2.0 ** -24


def _seed_images(scene, interest, eps):
    from .layers import covering_entries
    cam = scene.camera
    draws = [d for d in scene.draws if d.name in interest]
    h, w = cam.height, cam.width
    prep, pix, faces, sure, _, lo, hi = covering_entries([d.mesh for d in draws],
                                                         [d.model for d in draws], cam, "none",
                                                         eps)
    # a sliver's or degenerate face's depth interval is unbounded (±inf), but where a GPU
    # covers a pixel with it, the depth it shows interpolates the face's vertices: at most
    # their largest window depth (the far plane if a vertex is behind the eye), plus the
    # float32 slack
    free = ~np.isfinite(hi)
    if free.any():
        clip = prep.clip[prep.triangles.faces[faces[free]]]
        wv = clip[:, :, 3]
        with np.errstate(invalid="ignore", divide="ignore"):
            zv = 0.5 * clip[:, :, 2] / wv + 0.5
        zmax = np.where((wv > 0).all(axis=1), zv.max(axis=1), 1.0)
        hi = hi.copy()
        hi[free] = np.minimum(zmax + 16.0 * F32, 1.0)
    big = np.full(h * w, -np.inf)
    np.maximum.at(big, pix, hi)
    small = np.full(h * w, -np.inf)
    np.maximum.at(small, pix[sure], lo[sure])
    return (np.clip(big, 0.0, 1.0).reshape(h, w), np.isfinite(big).reshape(h, w),
            np.clip(small, 0.0, 1.0).reshape(h, w), np.isfinite(small).reshape(h, w))


def _floor_slope_max(seeded, cam, p, kw):
    """The largest floor-side slope m_f any seed may have: θ_f depends on the pixel only (φ is
    the angle of the pixel's ray to the floor), and m_f = −(P₂₂ + z)/tan θ_f is linear in z, so
    its largest value over the pixels that may be seeds is at z = −1 or z = +1."""
    from ..cutaway.surface import as_angles, seed_slopes
    theta = np.full(seeded.shape, float(np.min(as_angles(p["angle"]))))
    out = 0.0
    for z in (-1.0, 1.0):
        zz = np.where(seeded, z, -np.inf)
        slope, (slope_f, _) = seed_slopes(
            zz, theta, proj=cam.proj, view=cam.view,
            perspective_compensation=kw["perspective_compensation"],
            edge_compression=kw["edge_compression"], floor_normal=kw["floor_normal"],
            floor_margin=kw["floor_margin"])
        out = max(out, float(np.max(np.abs(slope))), float(np.max(np.abs(slope_f))))
    return out


def cutaway_bounds(scene, eps):
    """``(lo, hi)`` float32 (H, W): the window-depth interval of the cutaway depth D."""
    from ..cutaway.surface import cutaway_surface, pixel_ndc
    p = scene.parameters
    cam = scene.camera
    big, big_seed, small, small_seed = _seed_images(scene, set(p["interest"]), eps)
    kw = dict(proj=cam.proj, view=cam.view, angle=p["angle"],
              perspective_compensation=p["perspective_compensation"],
              edge_compression=p["edge_compression"])
    floor = p.get("floor_normal")
    if floor is not None:
        # the directional constraint: the same floor-constrained flood the scene's D used
        kw.update(floor_normal=np.asarray(floor, np.float64),
                  floor_margin=float(p.get("floor_margin", np.radians(2.0))))

    def flood(rear, seeded, variant):
        oid = np.where(seeded, 0, -1).astype(np.int32)
        return cutaway_surface(np.where(seeded, rear, 0.0), oid, variant=variant, **kw)

    from .. import render
    draws = [d for d in scene.draws if d.name in set(p["interest"])]
    rear = render([d.mesh for d in draws], **cam.kwargs, model=[d.model for d in draws],
                  depth_func="greater", clear_depth=0.0)
    own = np.asarray(rear.depth, np.float64), np.asarray(rear.object_id) >= 0
    d_hi = flood(big, big_seed, "exact")
    d_lo = np.full(d_hi.shape, np.inf)
    for v in p["accepted_variants"]:
        for seeds in ((small, small_seed), (big, big_seed), own):
            d_lo = np.minimum(d_lo, flood(*seeds, v))
    # float32 evaluation of z − m·‖x − s‖: the largest m times the diagonal in tangent units
    x, y = pixel_ndc(*d_hi.shape)
    diag = float(np.hypot(np.ptp(x), np.ptp(y))) / min(abs(cam.proj[0, 0]), abs(cam.proj[1, 1]))
    m_max = (abs(cam.proj[2, 2]) + 1.0) / np.tan(max(float(np.min(p["angle"])), 1e-3))
    if floor is not None:
        m_max = max(m_max, _floor_slope_max(big_seed, cam, p, kw))
    slack = 16.0 * F32 * (2.0 + m_max * diag)
    lo = 0.5 * (np.maximum(d_lo, -1.0) - slack) + 0.5
    hi = 0.5 * (d_hi + slack) + 0.5
    lo = np.clip(lo, 0.0, 1.0)
    hi = np.clip(hi, 0.0, 1.0)
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-1)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(2)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32), float(slack)
