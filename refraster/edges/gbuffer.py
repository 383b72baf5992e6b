"""The edge G-buffer (Nienhaus & Döllner, WSCG 2003, Sec. 4.1.1): pass 1 of the edge pipeline.

:func:`edge_gbuffer` turns a :class:`refraster.Framebuffer` into the paper's texture ``T_G``
(:class:`EdgeGBuffer`): eye-space normals encoded ``0.5·n + 0.5`` (RGB), linear depth normalized
to near/far planes fitted to the enhanced objects (A, :func:`fit_near_far`), and object ids. The
discontinuity operators of :mod:`refraster.edges.operators` read it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_float_array, as_real

__all__ = ["EdgeGBuffer", "fit_near_far", "edge_gbuffer", "gbuffer_of"]


@dataclass(frozen=True, eq=False)
class EdgeGBuffer:
    """The paper's texture ``T_G`` (Sec. 4.1.1) plus the id buffer, kept as floats.

    Attributes
    ----------
    normal : (H, W, 3) float32
        Encoded eye-space normals ``0.5·n + 0.5``; 0.5 in the background (``n = 0``).
    depth : (H, W) float32
        Linear depth ``(−z_eye − near) / (far − near)`` clipped to [0, 1]; 1 in the background.
    object_id : (H, W) int32
        Draw-call index; −1 in the background.
    near, far : float
        The planes the depth was normalized to.
    """

    normal: np.ndarray
    depth: np.ndarray
    object_id: np.ndarray
    near: float
    far: float

    @property
    def rgba(self):
        """``T_G`` as one ``(H, W, 4)`` float32 image: encoded normal in RGB, depth in A."""
        return np.concatenate([self.normal, self.depth[..., None]], axis=2)


def fit_near_far(view, *, bounds=None, meshes=None, models=None):
    """Near and far planes that exactly enclose the enhanced objects (Sec. 4.1.1).

    Parameters
    ----------
    view : (4, 4) float
        World → eye matrix.
    bounds : (2, 3) float, optional
        World-space axis-aligned box ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``; its eight
        corners are transformed to eye space.
    meshes, models : optional
        Used when ``bounds`` is None: the eye-space depth range of all vertices (the tightest
        bounding volume along the view axis). ``models`` has one 4×4 matrix per mesh.

    Returns
    -------
    near, far : float
        Smallest and largest ``−z_eye``; ``far > near`` (a flat range is widened by a relative
        1e-6 so that the normalization stays finite).
    """
    view = as_float_array(view, "view", shape=(4, 4))
    if bounds is not None:
        b = as_float_array(bounds, "bounds", shape=(2, 3))
        if np.any(b[1] < b[0]):
            raise ValueError(f"bounds must be [min, max] corners, got {b.tolist()}")
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2]]
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        z = -(corners @ view[2, :3] + view[2, 3])
    elif meshes:
        models = models if models is not None else [np.eye(4)] * len(meshes)
        z = np.concatenate([-(m.vertices @ (view @ mm)[2, :3] + (view @ mm)[2, 3])
                            for m, mm in zip(meshes, models)])
        if z.size == 0:
            raise ValueError("meshes have no vertices: cannot fit near and far")
    else:
        raise ValueError("give bounds, or meshes to fit near and far to")
    near, far = float(z.min()), float(z.max())
    if not far > near:
        far = near + max(abs(near), 1.0) * 1e-6
    return near, far


def edge_gbuffer(fb, *, bounds=None, near=None, far=None):
    """Pass 1 of the paper: the G-buffer the edge filters read.

    Parameters
    ----------
    fb : refraster.Framebuffer
        A render of the objects to enhance.
    bounds : (2, 3) float, optional
        World-space bounding box of the enhanced objects; near and far are fitted to it.
    near, far : float, optional
        Explicit planes (both or neither; exclusive with ``bounds``). When neither these nor
        ``bounds`` are given, near and far are fitted to the eye-space depth range of the
        framebuffer's meshes (:func:`fit_near_far`).

    Returns
    -------
    EdgeGBuffer

    Notes
    -----
    Nienhaus & Döllner, Sec. 4.1.1; MATH.md §3 (encoding ``c = (n + 1)/2``, background normal 0 →
    0.5, background depth 1 [guess]). The paper stores depth in an 8-bit alpha texture and fits
    near/far to fight its low precision; here depth stays float32, and the fit sets the scale
    that the depth thresholds refer to.
    """
    for attr in ("normal", "eye_depth", "object_id", "view"):
        if not hasattr(fb, attr):
            raise TypeError(f"fb must be a refraster.Framebuffer, got {type(fb).__name__}")
    if (near is None) != (far is None):
        raise ValueError("give both near and far, or neither")
    if near is not None:
        if bounds is not None:
            raise ValueError("give bounds or near/far, not both")
        near = as_real(near, "near")
        far = as_real(far, "far")
        if not far > near:
            raise ValueError(f"far must be greater than near, got near={near}, far={far}")
    else:
        near, far = fit_near_far(fb.view, bounds=bounds, meshes=fb.meshes, models=fb.models)
    return gbuffer_of(fb.normal, fb.eye_depth, fb.object_id, near, far)


def gbuffer_of(normal, eye_depth, object_id, near, far):
    """The :class:`EdgeGBuffer` of one image's eye-space ``normal (H, W, 3)``, ``eye_depth``
    and ``object_id (H, W)`` with the planes ``near``/``far`` (:func:`edge_gbuffer`'s
    encoding; a multisampled frame's sample ``s`` is such an image)."""
    normal = np.asarray(normal, np.float32)
    covered = np.asarray(object_id) >= 0
    half = np.float32(0.5)
    encoded = np.where(covered[..., None], half * normal + half, half).astype(np.float32)
    eye = np.where(covered, np.asarray(eye_depth, np.float64), far)
    depth = np.where(covered, np.clip((eye - near) / (far - near), 0.0, 1.0), 1.0)
    depth = depth.astype(np.float32)
    return EdgeGBuffer(normal=encoded, depth=depth,
                       object_id=np.ascontiguousarray(object_id, np.int32),
                       near=float(near), far=float(far))
