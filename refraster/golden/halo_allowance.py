"""Allowance of the 4D-halo scenes ("Goldens with teeth (2)", item 5).

A halo renderer's outputs are decided by thresholds: per voxel the slice triangle's coverage of
the voxel centre (its edges), the core test ``|2t − 1| < w_s + a``, Eq. 3's occlusion rule
``surf_d ≤ minD + ε`` and the halo radius (the thickened prism's outer face, t = 0 / 1), and per
slice which tetrahedra a plane ``z = c_k`` cuts (a plane through a vertex). A conformant
renderer evaluates each decisive quantity with its own rounding, so a voxel's class may differ
exactly where that quantity lies within ε of its threshold (its *margin* is below ε).

The margin test is done by evaluating the classification again with every threshold, and every
sample position, moved by ±ε (a voxel whose margin is below ε changes class under one of these
shifts, and only such voxels do: each test is monotone in its threshold):

==================  ==========================================================================
shift               ε and where it comes from
==================  ==========================================================================
sample position     ±1/16 pixel in x and in y: a rasterizer with 4 sub-pixel bits snaps the
                    slice triangles' vertices by up to 1/32 pixel; the fill rule (top-left or
                    llvmpipe's) differs only for centres on an edge, which the shift moves off
slice planes        ±``Z_REL``·max|z| (float32 rounding of the plane ``c_k`` and of the
                    tetrahedron vertices' z: a plane through a vertex)
w_s (and a)         ±``T_EPS`` on ``|2t − 1|``: t interpolated with float32 barycentrics
δt of Eq. 3         ±``T_EPS``
ε of the occlusion  ε·0 and ε·2 (float32 δ and minD: the ε of the rule is itself
rule                "1e-6·max|δ|", the size of float32 rounding of δ)
float32 vertices    the thickened vertices and their attributes rounded to float32
4 sub-pixel bits    the slice triangles snapped to 1/16 pixel instead of 1/256
==================  ==========================================================================

Per pixel: ``halo_class`` may take any class between the smallest and largest the variants
give (``halo_class_lo``, ``halo_class_hi``; equal to the golden's where no variant differs);
``alpha`` and ``color`` lie between the variants' smallest and largest value, widened by
``COMPOSITE_TOL`` for float32 compositing (48 back-to-front steps, each rounding at 2^-24, and
the float32 ``pow`` of the opacity correction). The variants' extremes bound the compositing
because accumulated opacity is increasing in every voxel's α and each colour step is bilinear
in (accumulated, α); a voxel's α and colour change only with its class or coverage, which the
variants span.
"""

from __future__ import annotations

import numpy as np

__all__ = ["halo_allowances", "halo_variants", "HALO_CHECKS"]

#: Sample-position shift (pixels): half of a 4-bit sub-pixel step, doubled for the fill rule.
XY_SHIFT = 1.0 / 16.0
#: Relative float32 rounding of slice planes and vertex z (a few units of 2^-24).
Z_REL = 4e-7
#: Error of |2t − 1| from float32 barycentrics (3 products and sums at 2^-24, times 2).
T_EPS = 1e-6
#: float32 compositing of alpha and colour over the slices.
COMPOSITE_TOL = 2e-4

HALO_CHECKS = {"halo_class": ("halo_class_lo", "halo_class_hi"),
               "alpha": ("alpha_lo", "alpha_hi"), "color": ("color_lo", "color_hi")}


def _surface(maps):
    from ..halos4d import Surface4D
    v = np.asarray(maps["surface_vertices4d"], np.float64)
    return Surface4D(v, np.asarray(maps["surface_faces"], np.int64),
                     np.asarray(maps["surface_tangents"], np.float64).reshape(len(v), 2, 4),
                     np.asarray(maps["surface_colors"], np.float64))


def render_variant(surface, p, *, dsw=0.0, ddt=0.0, eps_scale=1.0, dz=0.0, dxy=(0.0, 0.0),
                   f32=False, bits=None):
    """One halo render of the scene's parameters ``p`` with a threshold or sample shift.
    Returns (color (H, W, 3), alpha (H, W), volume (N, H, W)) float64 / int8."""
    from ..halos4d.render import (_render_bands, _screen_bounds, _bin_bands, BAND_ROWS,
                                  prepare, slice_alpha)
    from ..halos4d.slicing import SUBPIXEL_BITS, _slice, ortho_ndc, setup_window
    w, h, n = int(p["width"]), int(p["height"]), int(p["slices"])
    geo, rho = prepare(surface, rotation=np.asarray(p["rotation"], np.float64),
                       projection=p["projection"], rho=p.get("rho"))
    verts, attr = geo.vertices, geo.attributes
    if f32:
        verts = verts.astype(np.float32).astype(np.float64)
        attr = attr.astype(np.float32).astype(np.float64)
    sw = float(p["surface_width"])
    aa = float(p.get("antialias", sw))
    eps = 1e-6 * float(np.abs(geo.attributes[:, 0]).max()) * eps_scale
    bounds = _screen_bounds([geo.vertices], w, h, float(p["margin"]))
    step = (bounds[1, 2] - bounds[0, 2]) / n
    centres = bounds[0, 2] + (np.arange(n) + 0.5) * step + dz
    alpha = slice_alpha(float(p["opacity"]), step, rho, sw)
    v = verts.copy()
    v[:, 0] += dxy[0] * (bounds[1, 0] - bounds[0, 0]) / w
    v[:, 1] += dxy[1] * (bounds[1, 1] - bounds[0, 1]) / h
    st = _slice(v[:, 2].copy(), geo.tets, centres, attr, ortho_ndc(v, bounds))
    b = SUBPIXEL_BITS if bits is None else bits
    X, Y, order, bbox, valid, XF, YF = setup_window(st.xy, w, h, b)
    area = ((X[:, 1] - X[:, 0]) * (Y[:, 2] - Y[:, 0]) - (X[:, 2] - X[:, 0]) * (Y[:, 1] - Y[:, 0]))
    nbands = (h + BAND_ROWS - 1) // BAND_ROWS
    band_starts, band_lists = _bin_bands(bbox, valid, h, BAND_ROWS, nbands)
    rgb = np.zeros((h, w, 3))
    a = np.zeros((h, w))
    vol = np.zeros((n, h, w), np.int8)
    _render_bands(X, Y, XF, YF, order, bbox, area, st.slice, band_starts, band_lists, st.attr,
                  w, h, b, BAND_ROWS, float(p["delta_t"]) + ddt, float(p["delta_d"]), sw + dsw,
                  eps, alpha, bool(p["halos"]), aa, 0.0, np.zeros(3), False, 0.15, np.zeros(3),
                  True, rgb, a, vol)
    bg = np.asarray(p.get("background", [0.0, 0.0, 0.0]), np.float64)
    return rgb + (1.0 - a)[..., None] * bg, a, vol


def column_class(vol):
    """Per pixel the halo class of its column (the golden's ``halo_class``)."""
    return np.where((vol == 2).any(axis=0), 2, np.where(
        (vol == 1).any(axis=0), 1, np.where((vol == 3).any(axis=0), 3, 0))).astype(np.int32)


def halo_variants(p):
    """The shifts of the module docstring, as keyword sets of :func:`render_variant`."""
    zmax = max(abs(float(x)) for x in np.asarray(p["screen_bounds"], np.float64)[:, 2])
    out = [{}]
    for s in (-1.0, 1.0):
        out += [{"dxy": (s * XY_SHIFT, 0.0)}, {"dxy": (0.0, s * XY_SHIFT)},
                {"dz": s * Z_REL * max(zmax, 1.0)}, {"dsw": s * T_EPS}, {"ddt": s * T_EPS}]
    out += [{"eps_scale": 0.0}, {"eps_scale": 2.0}, {"f32": True}, {"bits": 4}]
    return out


def halo_allowances(scene):
    """``tolerance.npz`` arrays of a 4D-halo scene: per-pixel class range and alpha / colour
    intervals (module docstring)."""
    p = dict(scene.parameters)
    surface = _surface(scene.maps)
    cls, al, co = [], [], []
    for kw in halo_variants(p):
        rgb, a, vol = render_variant(surface, p, **kw)
        cls.append(column_class(vol))
        al.append(a)
        co.append(rgb)
    cls, al, co = np.stack(cls), np.stack(al), np.stack(co)
    ref = scene.buffers
    cls = np.concatenate([cls, np.asarray(ref["halo_class"], np.int32)[None]])
    al = np.concatenate([al, np.asarray(ref["alpha"], np.float64)[None]])
    co = np.concatenate([co, np.asarray(ref["color"], np.float64)[None]])
    out = {"halo_class_lo": cls.min(axis=0).astype(np.int32),
           "halo_class_hi": cls.max(axis=0).astype(np.int32)}
    for key, v in (("alpha", al), ("color", co)):
        out[f"{key}_lo"] = (v.min(axis=0) - COMPOSITE_TOL).astype(np.float32)
        out[f"{key}_hi"] = (v.max(axis=0) + COMPOSITE_TOL).astype(np.float32)
    return out
