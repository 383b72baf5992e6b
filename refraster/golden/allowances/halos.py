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
sample position     the corners (±2^−b, ±2^−b) pixel, ``b`` the candidate's declared sub-pixel
                    bits (:mod:`~refraster.golden.allowances.precision`; 1/256 at 8, 1/16 at
                    4): b bits snap each slice vertex by up to 2^−(b+1) pixel; a fill rule
                    differs only for centres on an edge; an edge function is affine in the
                    shift, so its extremes are at the corners
slice planes        ±``Z_REL``·max|z| (float32 rounding of the plane ``c_k`` and of the
                    tetrahedron vertices' z: a plane through a vertex)
w_s (and a)         ±``T_EPS`` on ``|2t − 1|``: t interpolated with float32 barycentrics
δt of Eq. 3         ±``T_EPS``
ε of the occlusion  ε·0 and ε·2 (float32 δ and minD: the ε of the rule is itself
rule                "1e-6·max|δ|", the size of float32 rounding of δ)
float32 vertices    the thickened vertices and their attributes rounded to float32
b sub-pixel bits    the slice triangles snapped to 2^−b pixel instead of 1/256 (b < 8)
==================  ==========================================================================

From the renders (the kernel's optional per-voxel colour and opacity, ``voxel_rgba``):

* per voxel, the set of classes the shifts give it; the column's ``halo_class`` (the voxels'
  class of highest priority, carved > surface > halo > empty) lies between every voxel at its
  lowest and some voxel at its highest (``halo_class_lo/hi``, as class numbers);
* per voxel, an opacity and colour box: α between the shifts' extremes (0 where a shift does not
  draw it); the largest α widened for the kink of ``|2t − 1|`` at t = ½ (its minimum over the
  shift square may lie inside: ``min − (max − min)`` of the sampled values is below it), and to
  the full slice opacity for a voxel drawn under some shifts only or whose carved / halo class
  changes (a rim or threshold voxel);
* the column's ``alpha`` and ``color`` bounds composited back to front from the boxes' ends
  (``A(1 − α) + α`` increasing in A and α; ``C(1 − α) + α·c`` increasing in C and c, affine in
  α), over the background, widened by ``COMPOSITE_TOL`` for float32 compositing.
"""

from __future__ import annotations

import numpy as np

__all__ = ["halo_allowances", "halo_variants", "HALO_CHECKS"]

def xy_shift(bits):
    """Sample-position shift (pixels): half of a ``bits``-bit sub-pixel step, doubled for the
    fill rule (1/16 at 4 bits, 1/256 at 8)."""
    return 2.0 ** -int(bits)
#: Relative float32 rounding of slice planes and vertex z (a few units of 2^-24).
Z_REL = 4e-7
#: Error of |2t − 1| from float32 barycentrics (3 products and sums at 2^-24, times 2).
T_EPS = 1e-6
#: float32 compositing of alpha and colour over the slices.
COMPOSITE_TOL = 1e-3

HALO_CHECKS = {"halo_class": ("halo_class_lo", "halo_class_hi"),
               "alpha": ("alpha_lo", "alpha_hi"), "color": ("color_lo", "color_hi")}


def _surface(maps):
    from ...halos4d import Surface4D
    v = np.asarray(maps["surface_vertices4d"], np.float64)
    return Surface4D(v, np.asarray(maps["surface_faces"], np.int64),
                     np.asarray(maps["surface_tangents"], np.float64).reshape(len(v), 2, 4),
                     np.asarray(maps["surface_colors"], np.float64))


def render_variant(surface, p, *, dsw=0.0, ddt=0.0, eps_scale=1.0, dz=0.0, dxy=(0.0, 0.0),
                   f32=False, bits=None, voxels=False):
    """One halo render of the scene's parameters ``p`` with a threshold or sample shift.
    Returns (color (H, W, 3), alpha (H, W), volume (N, H, W)) float64 / int8, and with
    ``voxels`` each drawn voxel's (r, g, b, α) (N, H, W, 4) (zero where not drawn)."""
    from ...halos4d import View4D
    from ...halos4d.render import _fused, _screen_bounds, _tet_slices, prepare, slice_alpha
    from ...halos4d.slicing import SUBPIXEL_BITS
    w, h, n = int(p["width"]), int(p["height"]), int(p["slices"])
    geo, rho = prepare(surface, view=View4D(rotation=np.asarray(p["rotation"], np.float64),
                                            projection=p["projection"]), rho=p.get("rho"),
                       split=p.get("split", "paper"))
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
    vox = np.zeros((n, h, w, 4))
    params = (float(p["delta_t"]) + ddt, float(p["delta_d"]), sw + dsw, eps, alpha,
              bool(p["halos"]), aa, 0.0, np.zeros(3), False, 0.15, np.zeros(3))
    rgb, a, vol = _fused(_tet_slices(v, geo.tets, centres, attr, bounds), w, h, params, True,
                         bits=SUBPIXEL_BITS if bits is None else bits, voxel_rgba=vox)[:3]
    bg = np.asarray(p.get("background", [0.0, 0.0, 0.0]), np.float64)
    if voxels:
        return rgb + (1.0 - a)[..., None] * bg, a, vol, vox, alpha
    return rgb + (1.0 - a)[..., None] * bg, a, vol


def _core_distance(va, alpha, sw, aa):
    """|2t − 1| of each drawn voxel recovered from its opacity ``1 − (1 − alpha)^cov``,
    ``cov = (w_s + a − |2t − 1|)/(2a)`` (NaN where not drawn; w_s − a where cov = 1)."""
    out = np.full(va.shape, np.nan)
    drawn = va > 0
    if aa <= 0.0 or alpha >= 1.0:
        out[drawn] = 0.0
        return out
    with np.errstate(divide="ignore", invalid="ignore"):
        cov = np.log1p(-va[drawn]) / np.log1p(-alpha)
    out[drawn] = np.clip(sw + aa - 2.0 * aa * np.minimum(cov, 1.0), 0.0, None)
    return out


def column_class(vol):
    """Per pixel the halo class of its column (the golden's ``halo_class``)."""
    return np.where((vol == 2).any(axis=0), 2, np.where(
        (vol == 1).any(axis=0), 1, np.where((vol == 3).any(axis=0), 3, 0))).astype(np.int32)


def halo_variants(p, bits=None):
    """The shifts of the module docstring, as keyword sets of :func:`render_variant`, for a
    candidate of ``bits`` sub-pixel bits (default the declared ones)."""
    from ...halos4d.slicing import SUBPIXEL_BITS
    from .precision import as_candidate_bits, candidate_bits
    bits = as_candidate_bits(candidate_bits() if bits is None else bits, "bits")
    shift = xy_shift(bits)
    zmax = max(abs(float(x)) for x in np.asarray(p["screen_bounds"], np.float64)[:, 2])
    out = [{}]
    for s in (-1.0, 1.0):
        # the square's corners: an edge function is affine in the shift, so its extremes over
        # the square are at the corners
        out += [{"dxy": (s * shift, shift)}, {"dxy": (s * shift, -shift)},
                {"dz": s * Z_REL * max(zmax, 1.0)}, {"dsw": s * T_EPS}, {"ddt": s * T_EPS}]
    out += [{"eps_scale": 0.0}, {"eps_scale": 2.0}, {"f32": True}]
    if bits < SUBPIXEL_BITS:
        out.append({"bits": bits})
    return out


def halo_allowances(scene, bits=None):
    """``tolerance.npz`` arrays of a 4D-halo scene: per-pixel class range and alpha / colour
    intervals (module docstring), for a candidate of ``bits`` sub-pixel bits (default the
    declared ones)."""
    p = dict(scene.parameters)
    surface = _surface(scene.maps)
    seen = None      # per voxel, the classes some shift gives it (bit c for class c)
    a_lo = a_hi = c_lo = c_hi = u_min = u_max = None
    sw = float(p["surface_width"])
    aa = float(p.get("antialias", sw))
    for kw in halo_variants(p, bits):
        rgb, a, vol, vox, alpha = render_variant(surface, p, voxels=True, **kw)
        u = _core_distance(vox[..., 3], alpha, sw, aa)
        u_min = u if u_min is None else np.fmin(u_min, u)
        u_max = u if u_max is None else np.fmax(u_max, u)
        bit = (np.int8(1) << vol.astype(np.int8)).astype(np.int8)
        va, vc = vox[..., 3], vox[..., :3]
        drawn = ((vol == 1) | (vol == 2) | (vol == 4))[..., None]    # a surface colour
        if seen is None:
            seen, a_lo, a_hi = bit, va, va.copy()
            c_lo = np.where(drawn, vc, np.inf)
            c_hi = np.where(drawn, vc, -np.inf)
        else:
            seen |= bit
            a_lo = np.minimum(a_lo, va)      # a voxel not drawn has α = 0
            a_hi = np.maximum(a_hi, va)
            c_lo = np.where(drawn, np.minimum(c_lo, vc), c_lo)
            c_hi = np.where(drawn, np.maximum(c_hi, vc), c_hi)
    # |2t − 1| is convex in the sample position (an affine t through a kink at t = ½), so its
    # smallest value over the shift square may lie inside it, where the voxel's α is largest:
    # with the centre and the corners sampled, min − (max − min) is below that minimum (if t
    # crosses ½ inside, the spread exceeds the smallest sampled value; if not, the minimum is a
    # sampled corner)
    if aa > 0.0 and alpha < 1.0:
        u_lo = np.maximum(0.0, u_min - (u_max - u_min))
        cov = np.clip((sw + aa - u_lo) / (2.0 * aa), 0.0, 1.0)
        a_hi = np.where(np.isfinite(u_lo), np.maximum(a_hi, 1.0 - (1.0 - alpha) ** cov), a_hi)
    # a voxel drawn under some shifts only lies on the rim of its slice triangle or of a class
    # region, and a carved one whose class changes is near a threshold: its sampled |2t − 1|
    # say nothing of the square's inside, so it may be drawn with the full slice opacity
    varies = (seen & (seen - 1)) != 0
    may_draw = ((seen & 2) != 0) | ((seen & 4) != 0)
    a_hi = np.where(may_draw & varies, np.maximum(a_hi, alpha), a_hi)
    # colours of voxels never drawn do not matter (α = 0 there)
    c_lo = np.where(np.isfinite(c_lo), c_lo, 0.0)
    c_hi = np.where(np.isfinite(c_hi), c_hi, 0.0)
    # the column's class is its voxels' class of highest priority (carved 2 > surface 1 >
    # halo 3 > empty 0); each voxel may independently take any class it took under a shift:
    # the column's class lies between the priority of every voxel at its lowest and of some
    # voxel at its highest
    rank_of = np.array([0, 2, 3, 1])           # class → priority rank
    cls_of = np.array([0, 3, 1, 2])            # rank → class
    lowest = np.zeros(seen.shape, np.int64)
    highest = np.zeros(seen.shape, np.int64)
    for c in (0, 3, 1, 2):                     # ascending priority
        has = (seen >> c) & 1 == 1
        highest = np.where(has, rank_of[c], highest)
    for c in (2, 1, 3, 0):                     # descending priority
        has = (seen >> c) & 1 == 1
        lowest = np.where(has, rank_of[c], lowest)
    r_lo, r_hi = lowest.max(axis=0), highest.max(axis=0)
    allowed = [(r_lo <= k) & (k <= r_hi) for k in range(4)]
    # as an interval of class numbers (the "bounds" check): the smallest and largest class
    # whose rank is allowed (a superset where the ranks' classes are not contiguous)
    lo = np.full(r_lo.shape, 3, np.int32)
    hi = np.zeros(r_lo.shape, np.int32)
    for k in range(4):
        lo = np.where(allowed[k], np.minimum(lo, cls_of[k]), lo)
        hi = np.where(allowed[k], np.maximum(hi, cls_of[k]), hi)
    out = {"halo_class_lo": lo.astype(np.int32), "halo_class_hi": hi.astype(np.int32)}
    # compositing bounds, back to front, each voxel independently within its (α, colour) box:
    # A_k = A(1 − α) + α is increasing in A and in α; C_k = C(1 − α) + α·c is increasing in C
    # and c and affine in α, so its extremes are at α's ends
    n_sl, h, w = seen.shape
    al_lo, al_hi = np.zeros((h, w)), np.zeros((h, w))
    cl_lo, cl_hi = np.zeros((h, w, 3)), np.zeros((h, w, 3))
    for k in range(n_sl):
        l, u = a_lo[k], a_hi[k]
        al_lo = al_lo * (1.0 - l) + l
        al_hi = al_hi * (1.0 - u) + u
        l3, u3 = l[..., None], u[..., None]
        cl_lo = np.minimum(cl_lo * (1.0 - l3) + l3 * c_lo[k], cl_lo * (1.0 - u3) + u3 * c_lo[k])
        cl_hi = np.maximum(cl_hi * (1.0 - l3) + l3 * c_hi[k], cl_hi * (1.0 - u3) + u3 * c_hi[k])
    bg = np.asarray(p.get("background", [0.0, 0.0, 0.0]), np.float64)
    # over the background: C + (1 − A)·bg, decreasing in A
    cl_lo = cl_lo + (1.0 - al_hi)[..., None] * bg
    cl_hi = cl_hi + (1.0 - al_lo)[..., None] * bg
    ref = scene.buffers
    for key, lo_, hi_, r in (("alpha", al_lo, al_hi, ref["alpha"]),
                             ("color", cl_lo, cl_hi, ref["color"])):
        r = np.asarray(r, np.float64)
        lo_ = np.minimum(lo_, r) - COMPOSITE_TOL
        hi_ = np.maximum(hi_, r) + COMPOSITE_TOL
        out[f"{key}_lo"] = np.clip(lo_, 0.0, 1.0).astype(np.float32)
        out[f"{key}_hi"] = np.clip(hi_, 0.0, 1.0).astype(np.float32)
    return out
