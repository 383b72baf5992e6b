"""The cutaway surface: rear hulls → per-seed slopes → jump flooding → NDC depth image.

The stage works in **NDC depth** z ∈ [−1, 1] (near = −1), as MATH.md §4.1 and D-C4 require, and
converts from and to window depth (``z_w = 0.5·z + 0.5``) at its boundary. Distances between
pixel centres are measured in **view-plane tangent units** (x_ndc/P00, y_ndc/P11), which are
isotropic in eye space, so a cutaway buffer whose pixels are not square (512² for a 640×480
frame, as in the paper) needs no special care: the row and column spacings simply differ.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_choice, as_float_array, as_matrix, as_real
from .flood import VARIANTS, exact, jump_flood

__all__ = [
    "cutaway_surface", "seed_slopes", "pixel_ndc", "tangent_sampling", "ndc_to_eye_depth",
    "unproject", "upsample_bilinear", "min_filter_3x3", "as_angles", "THETA_MIN",
    "FLOOR_MARGIN",
]

#: Smallest cutaway angle used (D-C2): θ → 0 means m → ∞; edge compression and the floor
#: constraint can drive θ to 0, so it is clamped here instead.
THETA_MIN = 1e-3
#: Default δ of the floor constraint (see :func:`seed_slopes`) [guess].
FLOOR_MARGIN = np.radians(2.0)


def _projection_kind(proj):
    """``"perspective"`` (last row (0, 0, −1, 0), as glFrustum) or ``"orthographic"`` (last row
    (0, 0, 0, 1), as glOrtho). Other matrices are rejected: D-C4's slope needs one of the two."""
    row = proj[3]
    if np.array_equal(row, [0.0, 0.0, -1.0, 0.0]):
        return "perspective"
    if np.array_equal(row, [0.0, 0.0, 0.0, 1.0]):
        return "orthographic"
    raise ValueError("proj must be an OpenGL perspective (last row 0, 0, −1, 0) or orthographic "
                     f"(last row 0, 0, 0, 1) matrix, got last row {row.tolist()}")


def pixel_ndc(height, width):
    """NDC (x, y) of the pixel centres of an ``(height, width)`` image, row 0 at the top."""
    x = (np.arange(width) + 0.5) * (2.0 / width) - 1.0
    y = 1.0 - (np.arange(height) + 0.5) * (2.0 / height)
    return np.broadcast_to(x[None, :], (height, width)), np.broadcast_to(y[:, None],
                                                                         (height, width))


def tangent_sampling(proj, height, width):
    """(row, column) spacing of pixel centres in view-plane tangent units (x_ndc/P00,
    y_ndc/P11); for an orthographic camera these are eye-space units. The row spacing is
    negative when ``P11`` is (NDC y down: rows run up the view plane)."""
    return 2.0 / (height * proj[1, 1]), 2.0 / (width * proj[0, 0])


def unproject(x_ndc, y_ndc, z_ndc, proj):
    """Eye-space positions ``(..., 3)`` of NDC points (inverse projection, divide by w)."""
    inv = np.linalg.inv(proj)
    p = np.stack([x_ndc, y_ndc, z_ndc, np.ones_like(z_ndc)], axis=-1) @ inv.T
    return p[..., :3] / p[..., 3:4]


def ndc_to_eye_depth(z_ndc, proj):
    """Eye depth −z_eye of NDC depths: z_e = (P23 − z·P33)/(z·P32 − P22)."""
    z = np.asarray(z_ndc, np.float64)
    return -(proj[2, 3] - z * proj[3, 3]) / (z * proj[3, 2] - proj[2, 2])


def _smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _slope_from_angle(theta, z_ndc, proj, kind, perspective_compensation):
    """m(s) in NDC depth per tangent unit (Eq. 3 as corrected, D-C2, D-C4)."""
    tan = np.tan(np.maximum(theta, THETA_MIN))
    if kind == "orthographic":
        # z_ndc changes by −P22 per eye unit of depth and tangent units are eye units: exact.
        return np.full(np.shape(z_ndc), -proj[2, 2]) / tan
    if perspective_compensation:
        # D-C4: exact for an anchor on the optical axis, −(PM_sz + z)/tan θ per tangent unit.
        return -(proj[2, 2] + z_ndc) / tan
    # The paper's basic surface (Sec. 3.2): a cone of angle θ in NDC (z_ndc against x_ndc),
    # i.e. cot θ per NDC-x unit, which is P00·cot θ per tangent unit.
    return np.full(np.shape(z_ndc), proj[0, 0]) / tan


def seed_slopes(z_ndc, theta, *, proj, view=None, perspective_compensation=True,
                edge_compression=0.1, floor_normal=None, floor_margin=FLOOR_MARGIN):
    """Per-seed slopes of the cutaway function on a cutaway buffer.

    Parameters
    ----------
    z_ndc : (Hc, Wc) float
        Seed (rear-hull) depths in NDC; ``-inf`` where there is no seed.
    theta : (Hc, Wc) float
        Cutaway angle θ(s) of each seed (per-object angles, Sec. 5.3), radians.
    proj, view : (4, 4) float
        Projection, and view matrix (needed only with ``floor_normal``, to bring it to eye space).
    perspective_compensation : bool
        Eq. 3 as corrected (D-C4); no effect for an orthographic camera (already exact).
    edge_compression : float or None
        r of Sec. 5.4 (D-C6): θ_e = θ·clamp01((1−|s_x|)/r)·clamp01((1−|s_y|)/r). None or 0: off.
    floor_normal : (3,) float or None
        World-space floor normal n̂ for the directional constraint (Sec. 5.5, D-C7).
    floor_margin : float
        δ ≥ 0 (radians): θ_f is clamped to φ − δ instead of φ [guess]. Objects resting on the
        floor have rear-hull seeds *on* the floor plane, where θ_f = φ makes the cutaway graze
        the floor and rounding (and the off-axis error of Eq. 3) decides pixel by pixel.

    Returns
    -------
    slope : (Hc, Wc) float64
        m_e(s).
    floor : None or (floor_slope (Hc, Wc), n_proj (Hc, Wc, 2))
        m_f(s) and the projected floor normal in tangent units (x right, y up).
    """
    kind = _projection_kind(proj)
    h, w = z_ndc.shape
    seeded = z_ndc > -np.inf
    z = np.where(seeded, z_ndc, 0.0)
    x_ndc, y_ndc = pixel_ndc(h, w)
    theta_e = np.array(theta, np.float64)
    if edge_compression:
        r = edge_compression
        theta_e = theta_e * np.clip((1.0 - np.abs(x_ndc)) / r, 0.0, 1.0) \
            * np.clip((1.0 - np.abs(y_ndc)) / r, 0.0, 1.0)
    slope = _slope_from_angle(theta_e, z, proj, kind, perspective_compensation)
    if floor_normal is None:
        return np.where(seeded, slope, 0.0), None
    rot = np.linalg.inv(view[:3, :3]).T
    n = rot @ floor_normal
    n = n / np.linalg.norm(n)
    pos = unproject(x_ndc, y_ndc, z, proj)
    if kind == "perspective":
        v = -pos / np.linalg.norm(pos, axis=-1, keepdims=True)
        # d/dε of the tangent coordinates x/(−z), y/(−z) of pos + ε·n (a positive multiple)
        n_proj = np.stack([-pos[..., 2] * n[0] + pos[..., 0] * n[2],
                           -pos[..., 2] * n[1] + pos[..., 1] * n[2]], axis=-1)
    else:
        v = np.broadcast_to(np.array([0.0, 0.0, 1.0]), pos.shape)
        n_proj = np.broadcast_to(n[:2], pos.shape[:2] + (2,)).copy()
    # D-C7: φ = arcsin(v̂·n̂), v̂ toward the camera, so φ > 0 when the camera is above the floor
    phi = np.arcsin(np.clip(v @ n, -1.0, 1.0))
    theta_f = np.clip(theta_e, 0.0, np.maximum(phi - floor_margin, 0.0)) \
        + theta_e * _smoothstep(0.0, np.pi / 18.0, -phi)
    slope_f = _slope_from_angle(theta_f, z, proj, kind, perspective_compensation)
    length = np.linalg.norm(n_proj, axis=-1, keepdims=True)
    n_proj = np.where(length > 1e-12, n_proj / np.where(length > 1e-12, length, 1.0), 0.0)
    return (np.where(seeded, slope, 0.0),
            (np.where(seeded, slope_f, 0.0), np.where(seeded[..., None], n_proj, 0.0)))


def as_angles(angle, name="angle"):
    """θ as a float64 array: one value (a scalar) or one per cutaway object; each in (0, π/2).
    ``name`` is the argument's name in the error messages."""
    if isinstance(angle, bool):
        raise TypeError(f"{name} must be a real number or a sequence of them, got bool")
    values = as_float_array(angle, name, finite=False)
    if values.ndim > 1 or values.size == 0:
        raise ValueError(f"{name} must be a scalar or a non-empty 1-D sequence, got shape "
                         f"{values.shape}")
    values = values.reshape(-1)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} must be finite, got {values.tolist()}")
    if np.any(values <= 0.0) or np.any(values >= np.pi / 2):
        raise ValueError(f"{name} must lie in (0, π/2) radians, got {values.tolist()}")
    return values


def cutaway_surface(rear_depth, object_id, *, proj, view=None, angle=np.pi / 6,
                    variant="jfa", perspective_compensation=True, edge_compression=0.1,
                    floor_normal=None, floor_margin=FLOOR_MARGIN, return_seeds=False):
    """The cutaway depth image D (NDC depth) from the rear hulls of the objects of interest.

    Parameters
    ----------
    rear_depth : (Hc, Wc) float
        Window depth of the rear hulls (rendered with depth test ``greater``), read only where
        ``object_id ≥ 0``.
    object_id : (Hc, Wc) int
        Which cutaway object each rear-hull pixel belongs to; −1 where none (not a seed).
    proj : (4, 4) float
        The frame's projection (perspective or orthographic).
    view : (4, 4) float, optional
        Needed with ``floor_normal``.
    angle : float or sequence of float
        Cutaway half-angle θ to the view vector, radians in (0, π/2); one per object id for
        local angles (Sec. 5.3).
    variant : {"jfa", "jfa+1", "jfa+2", "1+jfa", "exact"}
        Jump-flood schedule (:func:`refraster.cutaway.jump_flood`) or brute force; default
        ``"jfa"``, the paper's (as :class:`refraster.cutaway.Cutaway`).
    perspective_compensation, edge_compression, floor_normal, floor_margin
        See :func:`seed_slopes`.
    return_seeds : bool
        Also return the winning seed's (row, column).

    Returns
    -------
    D : (Hc, Wc) float64
        Cutaway depth in NDC, ≥ −1 (the near plane) everywhere.

    Notes
    -----
    MATH.md §4.1: D(x) = max_s [z_I(s) − m(s)‖x − s‖] with z_I = near (−1) where there is no
    object of interest. A near-plane seed contributes at most −1 (slopes are ≥ 0) and exactly −1
    at itself, so D = max(D_OOI, −1) with only the rear-hull pixels as seeds.
    """
    proj = as_matrix(proj, "proj")
    rear = as_float_array(rear_depth, "rear_depth", shape=(None, None))
    oid = np.asarray(object_id)
    if not np.issubdtype(oid.dtype, np.integer):
        raise TypeError(f"object_id must be an integer array, got dtype {oid.dtype}")
    if oid.shape != rear.shape:
        raise ValueError(f"object_id must have the shape of rear_depth {rear.shape}, "
                         f"got {oid.shape}")
    seeded = oid >= 0
    thetas = as_angles(angle)
    n_objects = int(oid.max()) + 1 if seeded.any() else 0
    if len(thetas) > 1 and n_objects > len(thetas):
        raise ValueError(f"object_id holds {n_objects} objects but angle has {len(thetas)} "
                         "entries")
    variant = as_choice(variant, "variant", VARIANTS + ("exact",))
    if edge_compression is not None:
        edge_compression = as_real(edge_compression, "edge_compression", lo=0.0)
    if floor_normal is not None:
        if view is None:
            raise ValueError("the floor constraint needs view (to bring floor_normal to eye space)")
        view = as_matrix(view, "view")
        floor_normal = as_float_array(floor_normal, "floor_normal", shape=(3,))
        if np.linalg.norm(floor_normal) == 0:
            raise ValueError("floor_normal must not be zero")
    floor_margin = as_real(floor_margin, "floor_margin", lo=0.0, hi=np.pi / 2)
    if np.any(seeded & ((rear < 0.0) | (rear > 1.0))):
        raise ValueError("rear_depth must be window depth in [0, 1] where object_id ≥ 0")
    z = np.where(seeded, 2.0 * rear - 1.0, -np.inf)
    theta = thetas[np.clip(oid, 0, None)] if len(thetas) > 1 else np.full(rear.shape, thetas[0])
    slope, floor = seed_slopes(z, theta, proj=proj, view=view,
                               perspective_compensation=bool(perspective_compensation),
                               edge_compression=edge_compression, floor_normal=floor_normal,
                               floor_margin=floor_margin)
    kwargs = dict(sampling=tangent_sampling(proj, *rear.shape), return_seeds=True)
    if floor is not None:
        kwargs.update(floor_slope=floor[0], floor_normal=floor[1])
    if variant == "exact":
        d, seeds = exact(z, slope, **kwargs)
    else:
        d, seeds = jump_flood(z, slope, variant=variant, **kwargs)
    d = np.maximum(d, -1.0)
    return (d, seeds) if return_seeds else d


def upsample_bilinear(image, height, width):
    """Bilinear resampling of ``image`` to ``(height, width)`` at pixel centres, clamped to the
    edge (a GL_LINEAR texture lookup with CLAMP_TO_EDGE, in float64)."""
    image = np.asarray(image, np.float64)
    h, w = image.shape
    if (h, w) == (height, width):
        return image.copy()
    v = np.clip((np.arange(height) + 0.5) * (h / height) - 0.5, 0.0, h - 1)
    u = np.clip((np.arange(width) + 0.5) * (w / width) - 0.5, 0.0, w - 1)
    i0 = np.floor(v).astype(np.int64)
    j0 = np.floor(u).astype(np.int64)
    i1 = np.minimum(i0 + 1, h - 1)
    j1 = np.minimum(j0 + 1, w - 1)
    fv = (v - i0)[:, None]
    fu = (u - j0)[None, :]
    top = image[i0][:, j0] * (1.0 - fu) + image[i0][:, j1] * fu
    bottom = image[i1][:, j0] * (1.0 - fu) + image[i1][:, j1] * fu
    return top * (1.0 - fv) + bottom * fv


def min_filter_3x3(image):
    """Minimum over each pixel's 3×3 neighbourhood (edge pixels use the neighbours that exist)."""
    padded = np.pad(np.asarray(image, np.float64), 1, mode="edge")
    h, w = image.shape
    out = padded[1:h + 1, 1:w + 1].copy()
    for di in range(3):
        for dj in range(3):
            np.minimum(out, padded[di:di + h, dj:dj + w], out=out)
    return out
