"""Cameras and OpenGL's coordinate conventions, documented once.

Conventions (the same as OpenGL's fixed-function pipeline):

* **Eye space** is right-handed; the camera sits at the origin looking down −Z with +Y up.
* **Matrices** are 4×4 ``float64`` applied to column vectors:
  ``clip = proj @ view @ model @ [x, y, z, 1]``.
* **Clip space → NDC** by dividing by ``w``; NDC is [−1, 1]³.
* **Window space**: ``x_w = (x_ndc + 1)·W/2``, ``y_w = (y_ndc + 1)·H/2`` with y up from the bottom
  edge (GL's window coordinates), ``depth = 0.5·z_ndc + 0.5`` in [0, 1]. Pixel centres are at
  half-integers.
* **Returned images** are ``(H, W, ...)`` arrays with **row 0 at the top**: the pixel whose GL
  window centre is ``(c + 0.5, y + 0.5)`` is stored at ``[H − 1 − y, c]``.

:func:`perspective`, :func:`frustum` and :func:`orthographic` build the same matrices as
``gluPerspective``, ``glFrustum`` and ``glOrtho``. The other APIs' conventions are fields of
:class:`refraster.RasterState` (``docs/architecture.md``, "Conventions"); the projections take
two keywords for them:

* ``depth_range="zero_to_one"``: the near plane maps to z_ndc = 0 and the far plane to 1
  (Vulkan, Direct3D, Metal, WebGPU), for a state with the same ``depth_range``;
* ``reversed=True``: near and far swap their depths (reversed-Z: near → 1, far → 0 under
  ``"zero_to_one"``; near → 1, far → −1 under OpenGL's range), drawn with ``depth_func``
  ``"greater"`` (or ``"gequal"``) and ``clear_depth=0``;
* ``far=math.inf`` (perspective and frustum): the limit of the matrix as far → ∞.

With ``z_ndc = (A·z_e + B) / (−z_e)`` and the depths ``d_n``, ``d_f`` the near and far planes map
to (OpenGL ``−1, 1``; reversed ``1, −1``; zero-to-one ``0, 1``; reversed zero-to-one ``1, 0``)::

    A = (d_n·n − d_f·f) / (f − n),   B = (d_n − d_f)·n·f / (f − n)
    far = ∞:   A = −d_f,   B = (d_n − d_f)·n

so reversed-Z with an infinite far plane in ``"zero_to_one"`` is ``A = 0, B = n``: ``z_ndc =
n / −z_e``, exactly 1 at ``z_e = −n`` and → 0 as ``z_e → −∞`` (the float32 depth keeps its
relative precision over the whole range). OpenGL's (default) matrices are computed by the
formulas of ``gluPerspective``/``glFrustum``/``glOrtho`` as before.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from ._validate import as_float_array, as_real, as_image_size, as_matrix

__all__ = [
    "look_at", "perspective", "frustum", "orthographic", "viewport", "Camera", "frame_bounds",
]


def _norm(v):
    """``np.linalg.norm(v)`` (the same bytes), or where its squares overflow or underflow
    (a coordinate beyond ~1e154 or below ~1e-154) the norm of ``v`` scaled by its largest
    entry first, without a warning."""
    with np.errstate(over="ignore", under="ignore"):
        n = np.linalg.norm(v)
    if np.isfinite(n) and (n > 0.0 or not np.any(v)):
        return n
    m = float(np.abs(v).max())
    return m * np.linalg.norm(v / m)


def look_at(eye, target, up=(0.0, 1.0, 0.0)):
    """View matrix of a camera at ``eye`` looking at ``target`` (``gluLookAt``).

    Parameters
    ----------
    eye, target, up : (3,) float
        Positions in world space; ``up`` must not be parallel to ``target − eye``.

    Returns
    -------
    (4, 4) float64 world → eye matrix.
    """
    eye = as_float_array(eye, "eye", shape=(3,))
    target = as_float_array(target, "target", shape=(3,))
    up = as_float_array(up, "up", shape=(3,))
    with np.errstate(over="ignore"):
        f = target - eye
    if not np.all(np.isfinite(f)):
        raise ValueError("eye and target are too far apart: target − eye overflows float64")
    nf = _norm(f)
    if nf == 0.0:
        raise ValueError("eye and target must differ")
    f = f / nf
    s = np.cross(f, up)
    ns = _norm(s)
    if ns <= 1e-12 * max(1.0, _norm(up)):
        raise ValueError("up must not be parallel to the viewing direction target − eye")
    s = s / ns
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3] = s
    m[1, :3] = u
    m[2, :3] = -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


#: The clip-space depth ranges a projection can be built for (``RasterState.depth_range``).
DEPTH_RANGES = ("negative_one_to_one", "zero_to_one")


def _depths(depth_range, reversed):
    """``(d_n, d_f)``: the NDC depths the near and far planes map to."""
    if not isinstance(reversed, (bool, np.bool_)):
        raise TypeError(f"reversed must be a bool, got {type(reversed).__name__}")
    if not isinstance(depth_range, str) or depth_range not in DEPTH_RANGES:
        raise ValueError(f"depth_range must be one of {', '.join(DEPTH_RANGES)}; got "
                         f"{depth_range!r}")
    d_n, d_f = (-1.0, 1.0) if depth_range == "negative_one_to_one" else (0.0, 1.0)
    return (d_f, d_n) if reversed else (d_n, d_f)


def _near_far(near, far, *, infinite):
    n = as_real(near, "near", lo=0.0, lo_open=True)
    if infinite and isinstance(far, numbers.Real) and not isinstance(far, bool) \
            and far == math.inf:
        return n, math.inf
    f = as_real(far, "far")
    if not f > n:
        raise ValueError(f"far must be greater than near, got near={n}, far={f}")
    return n, f


_F32 = np.finfo(np.float32)
#: What each entry of a projection is, for the message that names one beyond float32.
_TERMS = {(0, 0): "x scale", (1, 1): "y scale", (0, 2): "x shift", (1, 2): "y shift",
          (0, 3): "x offset", (1, 3): "y offset", (2, 2): "depth scale",
          (2, 3): "depth offset"}


def _within_float32(m, what):
    """Refuse a projection with a non-zero entry outside float32's normal numbers (the vertex
    stage multiplies in float32: a smaller entry flushes to zero, a larger one overflows, and the
    frame loses its depth or its extent). ``what``: the call and its arguments."""
    tiny, big = float(_F32.tiny), float(_F32.max)
    for (i, j), value in np.ndenumerate(m):
        if value != 0.0 and not tiny <= abs(value) <= big:
            raise ValueError(
                f"{what}: the projection's {_TERMS.get((i, j), 'entry')} [{i}, {j}] = "
                f"{value:.3g} is outside float32's range ({tiny:.3g} to {big:.3g} in magnitude), "
                f"the precision the vertex stage multiplies in; it would "
                f"{'flush to zero' if abs(value) < tiny else 'overflow'} there")
    return m


def _perspective_depth(m, n, f, d_n, d_f):
    """Rows 2 of a perspective matrix for the near and far depths ``d_n``, ``d_f`` (the
    module's formulas; ``f = inf``: the limit)."""
    if f == math.inf:
        m[2, 2] = 0.0 - d_f   # +0.0, not −0.0, when d_f = 0
        m[2, 3] = (d_n - d_f) * n
    else:
        m[2, 2] = (d_n * n - d_f * f) / (f - n)
        m[2, 3] = (d_n - d_f) * n * f / (f - n)


def frustum(left, right, bottom, top, near, far, *, reversed=False,
            depth_range="negative_one_to_one"):
    """Perspective projection of ``glFrustum``; ``0 < near < far`` (``far`` may be
    ``math.inf``). ``depth_range`` and ``reversed``: the near and far planes' depths (module
    docstring)."""
    d_n, d_f = _depths(depth_range, reversed)
    l, r = as_real(left, "left"), as_real(right, "right")
    b, t = as_real(bottom, "bottom"), as_real(top, "top")
    n, f = _near_far(near, far, infinite=True)
    if r == l or t == b:
        raise ValueError("left/right and bottom/top must differ")
    m = np.zeros((4, 4))
    m[0, 0] = 2 * n / (r - l)
    m[0, 2] = (r + l) / (r - l)
    m[1, 1] = 2 * n / (t - b)
    m[1, 2] = (t + b) / (t - b)
    if (d_n, d_f) == (-1.0, 1.0) and f != math.inf:   # glFrustum's own formulas
        m[2, 2] = -(f + n) / (f - n)
        m[2, 3] = -2 * f * n / (f - n)
    else:
        _perspective_depth(m, n, f, d_n, d_f)
    m[3, 2] = -1.0
    return _within_float32(m, f"frustum(left={l:g}, right={r:g}, bottom={b:g}, top={t:g}, "
                              f"near={n:g}, far={f:g})")


def perspective(fovy, aspect, near, far, *, reversed=False, depth_range="negative_one_to_one"):
    """Perspective projection of ``gluPerspective``; ``fovy`` in **degrees**, ``0 < near <
    far`` (``far`` may be ``math.inf``). ``depth_range`` and ``reversed``: the near and far
    planes' depths (module docstring).

    Examples
    --------
    Reversed-Z with an infinite far plane, as modern engines render (with
    ``RasterState(depth_range="zero_to_one", depth_func="greater", clear_depth=0.0)``):

    >>> import math
    >>> p = perspective(60, 4 / 3, 0.1, math.inf, reversed=True, depth_range="zero_to_one")
    >>> float(p[2, 2]), float(p[2, 3]), float(p[3, 2])
    (0.0, 0.1, -1.0)
    """
    d_n, d_f = _depths(depth_range, reversed)
    fovy = as_real(fovy, "fovy", lo=0.0, hi=180.0, lo_open=True, hi_open=True)
    aspect = as_real(aspect, "aspect", lo=0.0, lo_open=True)
    near, far = _near_far(near, far, infinite=True)
    f = 1.0 / np.tan(np.radians(fovy) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    if (d_n, d_f) == (-1.0, 1.0) and far != math.inf:   # gluPerspective's own formulas
        m[2, 2] = (far + near) / (near - far)
        m[2, 3] = 2 * far * near / (near - far)
    else:
        _perspective_depth(m, near, far, d_n, d_f)
    m[3, 2] = -1.0
    return _within_float32(m, f"perspective(fovy={fovy:g}, aspect={aspect:g}, near={near:g}, "
                              f"far={far:g})")


def orthographic(left, right, bottom, top, near, far, *, reversed=False,
                 depth_range="negative_one_to_one"):
    """Orthographic projection of ``glOrtho``. ``depth_range`` and ``reversed``: the near and
    far planes' depths ``d_n``, ``d_f`` (module docstring): ``z_ndc = A·z_e + B`` with
    ``A = (d_n − d_f) / (f − n)``, ``B = (d_n·f − d_f·n) / (f − n)``."""
    d_n, d_f = _depths(depth_range, reversed)
    l, r = as_real(left, "left"), as_real(right, "right")
    b, t = as_real(bottom, "bottom"), as_real(top, "top")
    n, f = as_real(near, "near"), as_real(far, "far")
    if r == l or t == b or f == n:
        raise ValueError("orthographic: left/right, bottom/top and near/far must differ")
    m = np.eye(4)
    m[0, 0] = 2 / (r - l)
    m[1, 1] = 2 / (t - b)
    m[0, 3] = -(r + l) / (r - l)
    m[1, 3] = -(t + b) / (t - b)
    if (d_n, d_f) == (-1.0, 1.0):   # glOrtho's own formulas
        m[2, 2] = -2 / (f - n)
        m[2, 3] = -(f + n) / (f - n)
    else:
        m[2, 2] = (d_n - d_f) / (f - n)
        m[2, 3] = (d_n * f - d_f * n) / (f - n)
    return _within_float32(m, f"orthographic(left={l:g}, right={r:g}, bottom={b:g}, "
                              f"top={t:g}, near={n:g}, far={f:g})")


def viewport(width, height, *, depth_range="negative_one_to_one"):
    """NDC → window matrix (GL window coordinates, y up; window depth ``0.5·z + 0.5``, or
    ``z`` under ``depth_range="zero_to_one"``)."""
    _depths(depth_range, False)
    width, height = as_image_size(width, height)
    m = np.eye(4)
    m[0, 0] = m[0, 3] = width / 2.0
    m[1, 1] = m[1, 3] = height / 2.0
    if depth_range == "negative_one_to_one":
        m[2, 2] = m[2, 3] = 0.5
    else:
        m[2, 3] = 0.0
    return m


def is_perspective(proj):
    """True when ``proj`` has a perspective row (its last row is not (0, 0, 0, 1))."""
    proj = np.asarray(proj)
    return not (proj[3, 0] == 0 and proj[3, 1] == 0 and proj[3, 2] == 0)


@dataclass(frozen=True)
class Camera:
    """A view and projection matrix with the viewport size they are meant for."""

    view: np.ndarray
    proj: np.ndarray
    width: int
    height: int

    def __post_init__(self):
        object.__setattr__(self, "view", as_matrix(self.view, "view"))
        object.__setattr__(self, "proj", as_matrix(self.proj, "proj"))
        w, h = as_image_size(self.width, self.height)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)

    @property
    def kwargs(self):
        """``dict(view=..., proj=..., width=..., height=...)`` for :func:`refraster.render`."""
        return dict(view=self.view, proj=self.proj, width=self.width, height=self.height)

    @property
    def near_far(self):
        """(near, far) distances recovered from the projection matrix."""
        return near_far(self.proj)


def near_far(proj, *, reversed=False, depth_range="negative_one_to_one"):
    """The near and far plane distances of a perspective or orthographic matrix built for
    ``depth_range`` and ``reversed`` (GL's by default); far is ``inf`` for an infinite one."""
    d_n, d_f = _depths(depth_range, reversed)
    p = as_matrix(proj, "proj")
    a, b = p[2, 2], p[2, 3]
    if (d_n, d_f) == (-1.0, 1.0):
        if is_perspective(p):
            return b / (a - 1.0), (b / (a + 1.0) if a + 1.0 != 0.0 else math.inf)
        return (b + 1.0) / a, (b - 1.0) / a
    if is_perspective(p):   # z_ndc = −a − b / z_e: the distance where it equals d is b / (d + a)
        return tuple(b / (d + a) if d + a != 0.0 else math.inf for d in (d_n, d_f))
    return (b - d_n) / a, (b - d_f) / a


def frame_bounds(bounds, *, width, height, fovy=35.0, direction=(1.0, 0.8, 1.4), up=(0, 1, 0),
                 margin=1.1):
    """A camera that frames an axis-aligned box ``bounds = [[xmin,ymin,zmin],[xmax,ymax,zmax]]``.

    The eye looks at the box centre from ``direction`` at a distance where the bounding sphere
    fits the vertical and horizontal field of view; near and far enclose the sphere.
    """
    bounds = as_float_array(bounds, "bounds", shape=(2, 3))
    width, height = as_image_size(width, height)
    centre = bounds.mean(axis=0)
    radius = max(0.5 * float(np.linalg.norm(bounds[1] - bounds[0])), 1e-9) * margin
    d = as_float_array(direction, "direction", shape=(3,))
    nd = _norm(d)
    if nd == 0.0:
        raise ValueError("direction must not be the zero vector")
    d = d / nd
    aspect = width / height
    fovy = as_real(fovy, "fovy", lo=0.0, hi=180.0, lo_open=True, hi_open=True)
    half = np.radians(fovy) / 2
    half_h = np.arctan(np.tan(half) * min(aspect, 1.0))
    dist = radius / np.sin(half_h)
    eye = centre + d * dist
    view = look_at(eye, centre, up)
    near = max(dist - radius * 1.05, dist * 1e-3)
    far = dist + radius * 1.05
    if not far > near:
        raise ValueError(f"fovy={fovy:g}: too narrow a field of view to frame these bounds: the "
                         f"eye would stand {dist:.3g} away from a bounding sphere of radius "
                         f"{radius:.3g}, where near and far round to the same distance")
    return Camera(view, perspective(fovy, aspect, near, far), width, height)
