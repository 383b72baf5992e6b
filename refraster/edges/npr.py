"""NPR styles combined with the edge map (Nienhaus & Döllner, WSCG 2003, Sec. 5).

Each style shades the visible surface from the G-buffer's eye-space normals; :func:`composite`
then blends the edge map over it as the paper's fragment shading does: inner edges towards
white by the RGB strength, then profile edges towards black by the alpha strength (MATH.md
§3.1–3.2).

* :func:`gooch` — Gooch et al.'s cool-to-warm model for technical illustration (Sec. 5.1).
* :func:`toon` — Lake et al.'s 1D shade texture with nearest filtering (Sec. 5.4), and
  :func:`cartoon_map`, the paper's anti-aliased variant.
* :func:`hatching` — edge-enhanced hatching (Sec. 5.2): a procedural prioritized stroke texture
  (:func:`stroke_texture`) thresholded with Freudenberg et al.'s smooth threshold
  (:func:`smooth_threshold`).

Light directions are eye-space vectors pointing *towards* the light; they are normalized.
Colours are RGB in [0, 1]; outputs are ``(H, W, 3)`` float32.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from .._config import PJIT
from .._validate import as_float_array, as_real, check_shape

__all__ = [
    "DEFAULT_LIGHT", "DEFAULT_TOON_TEXTURE", "gooch", "toon", "cartoon_map", "stroke_texture",
    "triplanar_strokes", "surface_strokes", "object_space", "smooth_threshold", "hatching",
    "composite", "reflection", "render_mirrored", "MirrorStyle", "MirrorRender",
]

#: Towards the light, in eye space: above, left and in front of the viewer.
DEFAULT_LIGHT = (-0.4, 0.6, 1.0)
#: Lake et al.'s shade texture: shadowed, lit and highlighted bands (multiplied by the colour).
DEFAULT_TOON_TEXTURE = (0.45, 0.75, 1.0)


def _normals(normal):
    n = as_float_array(normal, "normal", dtype=np.float64)
    check_shape(n, "normal", (None, None, 3))
    return n


def _mask(mask, normal):
    """``None`` → pixels with a non-zero normal (the G-buffer's background normal is 0)."""
    if mask is None:
        return np.any(normal != 0.0, axis=2)
    m = np.asarray(mask)
    if m.dtype != np.bool_:
        raise TypeError(f"mask must be a bool array, got dtype {m.dtype}")
    check_shape(m, "mask", normal.shape[:2])
    return m


def _color(value, name):
    c = as_float_array(value, name, shape=(3,))
    if np.any(c < 0.0) or np.any(c > 1.0):
        raise ValueError(f"{name} must lie in [0, 1], got {c.tolist()}")
    return c


def _light(light):
    d = as_float_array(light, "light", shape=(3,))
    length = float(np.linalg.norm(d))
    if length == 0.0:
        raise ValueError("light must be a non-zero direction")
    return d / length


def _finish(rgb, mask, background):
    out = np.full(mask.shape + (3,), background, np.float32)
    out[mask] = np.clip(rgb[mask], 0.0, 1.0)
    return out


def gooch(normal, *, light=DEFAULT_LIGHT, base=(0.75, 0.75, 0.75), cool=(0.0, 0.0, 0.55),
          warm=(0.3, 0.3, 0.0), alpha=0.25, beta=0.5, mask=None, background=(1.0, 1.0, 1.0)):
    """Gooch cool-to-warm shading for technical illustration.

    Parameters
    ----------
    normal : (H, W, 3) float
        Eye-space unit normals (``Framebuffer.normal``); 0 in the background.
    light : (3,) float
        Towards the light, eye space.
    base : (3,) float
        The object's diffuse colour ``k_d``.
    cool, warm : (3,) float
        ``k_blue`` and ``k_yellow``.
    alpha, beta : float in [0, 1]
        How much of ``k_d`` is mixed into the cool and warm tones.
    mask : (H, W) bool, optional
        Pixels to shade (default: those with a non-zero normal).
    background : (3,) float

    Returns
    -------
    (H, W, 3) float32
        ``t·k_warm + (1 − t)·k_cool`` with ``t = (1 + n·l) / 2``, ``k_cool = cool + α·k_d``,
        ``k_warm = warm + β·k_d``, clipped to [0, 1].

    Notes
    -----
    Gooch, Gooch, Shirley & Cohen, SIGGRAPH 1998, Sec. 4.2 (the paper's [Goo98a]), as used by
    Nienhaus & Döllner Sec. 5.1. The equation is often quoted with ``k_cool`` weighted by
    ``(1 + l·n)/2``, which would put the cool tone on the lit side, against Gooch et al.'s text
    ("warm towards the light") and figures; here the warm tone faces the light.
    """
    n = _normals(normal)
    m = _mask(mask, n)
    lt = _light(light)
    kd = _color(base, "base")
    a = as_real(alpha, "alpha", lo=0.0, hi=1.0)
    b = as_real(beta, "beta", lo=0.0, hi=1.0)
    k_cool = _color(cool, "cool") + a * kd
    k_warm = _color(warm, "warm") + b * kd
    t = (0.5 * (1.0 + n @ lt))[..., None]
    return _finish(t * k_warm + (1.0 - t) * k_cool, m, _color(background, "background"))


def _texture(texture):
    tex = as_float_array(texture, "texture")
    if tex.ndim == 1:
        tex = tex[:, None]
    if tex.ndim != 2 or tex.shape[1] not in (1, 3) or tex.shape[0] == 0:
        raise ValueError(f"texture must have shape (N,) or (N, 3) with N >= 1, got {tex.shape}")
    if np.any(tex < 0.0) or np.any(tex > 1.0):
        raise ValueError("texture values must lie in [0, 1]")
    return tex


def toon(normal, *, light=DEFAULT_LIGHT, texture=DEFAULT_TOON_TEXTURE, color=(0.9, 0.6, 0.35),
         mask=None, background=(1.0, 1.0, 1.0)):
    """Cartoon shading through a 1D texture with nearest filtering.

    Parameters
    ----------
    normal : (H, W, 3) float
    light : (3,) float
    texture : (N,) or (N, 3) float in [0, 1]
        The shade texture; texel ``i`` covers ``u ∈ [i/N, (i+1)/N)``. Values multiply
        ``color``.
    color : (3,) float
    mask : (H, W) bool, optional
    background : (3,) float

    Returns
    -------
    (H, W, 3) float32
        ``color · texture[min(⌊u·N⌋, N − 1)]`` with ``u = max(n·l, 0)``: nearest filtering with
        clamp-to-edge, as ``GL_NEAREST`` samples texel ``⌊u·N⌋``.

    Notes
    -----
    Lake, Marshall, Harris & Blackstein, NPAR 2000 (the paper's [Lak00a]); Nienhaus & Döllner
    Sec. 5.4. The hard band boundaries are the "artifacts between consecutive color patches"
    that :func:`cartoon_map` smooths.
    """
    n = _normals(normal)
    m = _mask(mask, n)
    lt = _light(light)
    tex = _texture(texture)
    col = _color(color, "color")
    u = np.maximum(n @ lt, 0.0)
    texel = np.minimum(np.floor(u * len(tex)).astype(np.int64), len(tex) - 1)
    return _finish(tex[texel] * col, m, _color(background, "background"))


@njit(**PJIT)
def _cartoon_kernel(img, mask, out):
    h, w = mask.shape
    for y in prange(h):
        for x in range(w):
            if not mask[y, x]:
                for c in range(3):
                    out[y, x, c] = img[y, x, c]
                continue
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            total = 0.0
            for dy in range(-1, 2):
                yy = min(max(y + dy, 0), h - 1)
                for dx in range(-1, 2):
                    xx = min(max(x + dx, 0), w - 1)
                    if mask[yy, xx]:
                        wgt = (2.0 - abs(dy)) * (2.0 - abs(dx))
                        acc0 += wgt * img[yy, xx, 0]
                        acc1 += wgt * img[yy, xx, 1]
                        acc2 += wgt * img[yy, xx, 2]
                        total += wgt
            out[y, x, 0] = acc0 / total
            out[y, x, 1] = acc1 / total
            out[y, x, 2] = acc2 / total


def cartoon_map(image, *, mask=None):
    """The paper's anti-aliased cartoon map: the cartoon shading resampled over 3×3 texels.

    Parameters
    ----------
    image : (H, W, 3) float
        A :func:`toon` rendering.
    mask : (H, W) bool, optional
        Covered pixels. Only covered neighbours are averaged, so the background does not bleed
        into the object (default: every pixel is covered).

    Returns
    -------
    (H, W, 3) float32
        At covered pixels the normalized binomial average ``[1 2 1]ᵀ[1 2 1]/16`` of the covered
        neighbours (clamp-to-edge borders); other pixels are copied.

    Notes
    -----
    Nienhaus & Döllner Sec. 5.4: "we sample that texture to anti-alias its contents". The
    filter is not given; the binomial 3×3 is a guess (the smallest symmetric low-pass that
    reads the same neighbours as the edge operators).
    """
    img = as_float_array(image, "image")
    check_shape(img, "image", (None, None, 3))
    if mask is None:
        m = np.ones(img.shape[:2], np.bool_)
    else:
        m = np.asarray(mask)
        if m.dtype != np.bool_:
            raise TypeError(f"mask must be a bool array, got dtype {m.dtype}")
        check_shape(m, "mask", img.shape[:2])
        m = np.ascontiguousarray(m)
    out = np.zeros(img.shape, np.float32)
    if img.size:
        _cartoon_kernel(img, m, out)
    return out


def stroke_texture(height, width, *, spacing=6.0, angle=45.0, cross_angle=-45.0,
                   first=0.9, cross=0.5):
    """A procedural prioritized stroke texture (a hatching threshold map) in screen space.

    Parameters
    ----------
    height, width : int
    spacing : float > 0
        Distance between strokes of one family, in pixels.
    angle, cross_angle : float
        Directions of the first and the cross-hatching strokes, degrees from the +x axis.
    first, cross : float in (0, 1]
        Tones below which the first and the cross family start to appear.

    Returns
    -------
    (H, W) float32 in [0, 1]
        The priority ``T = max(first·(1 − d₁), cross·(1 − d₂))``, where ``d`` is the distance to
        the nearest stroke centre line in units of half the spacing. Thresholding a tone ``I``
        against it inks where ``T > I``: as the tone darkens, strokes grow from their centre
        lines, and cross strokes join below ``cross``.

    Notes
    -----
    The paper's "prioritized stroke texture" (Sec. 5.2, after Praun et al. and Freudenberg et
    al.) is an image; this procedural one is a guess with the same property: the inked set
    grows monotonically as the tone darkens.
    """
    from .._validate import as_image_size
    width, height = as_image_size(width, height)
    s = as_real(spacing, "spacing", lo=0.0, lo_open=True)
    a1 = np.radians(as_real(angle, "angle"))
    a2 = np.radians(as_real(cross_angle, "cross_angle"))
    t1 = as_real(first, "first", lo=0.0, hi=1.0, lo_open=True)
    t2 = as_real(cross, "cross", lo=0.0, hi=1.0, lo_open=True)
    y, x = np.mgrid[0:height, 0:width] + 0.5
    y = -y  # angles count counter-clockwise on screen, with row 0 at the top
    return _priority(x, y, s, a1, a2, t1, t2).astype(np.float32)


def _priority(x, y, s, a1, a2, t1, t2):
    """The prioritized stroke texture at plane coordinates (x, y): two families of parallel
    strokes, ``T = max(t1·(1 − d₁), t2·(1 − d₂))``, d in half spacings."""

    def family(a):
        u = (x * np.cos(a) + y * np.sin(a)) / s
        return 1.0 - 2.0 * np.abs(u - np.round(u))

    return np.maximum(t1 * family(a1), t2 * family(a2))


def triplanar_strokes(position, normal, *, spacing, angle=45.0, cross_angle=-45.0, first=0.9,
                      cross=0.5, sharpness=8.0, mask=None):
    """The prioritized stroke texture attached to the surface by a triplanar projection.

    Parameters
    ----------
    position : (H, W, 3) float
        Object-space position of the visible surface (:func:`object_space`).
    normal : (H, W, 3) float
        Object-space unit normal there.
    spacing : float > 0
        Distance between strokes of one family, in object units.
    angle, cross_angle, first, cross : float
        As :func:`stroke_texture`, in each projection plane.
    sharpness : float >= 0
        Exponent k of the blend weights ``w_i = |n_i|^k / Σ_j |n_j|^k``: 0 averages the three
        projections, large k picks the dominant axis (narrow blend zones).
    mask : (H, W) bool, optional
        Pixels to texture (default: those with a non-zero normal); others get 1 (paper).

    Returns
    -------
    (H, W) float32
        ``T = Σ_i w_i T_i``, where ``T_i`` is the stroke priority of the plane coordinates of
        the projection along axis i: along x ``(y, z)``, along y ``(z, x)``, along z ``(x, y)``.

    Notes
    -----
    The paper's strokes are a texture on the surface (Sec. 5.2, after Freudenberg et al. and
    Praun et al.), so they stay on the object when it or the camera moves. Our meshes have no
    texture coordinates; a triplanar projection needs only the fragment's object position and
    normal, keeps the stroke spacing within a factor √3 of ``spacing`` on every orientation
    (one planar projection stretches strokes without bound on faces parallel to it; spherical
    or cylindrical ones have poles and seams) and is a few lines of a fragment shader [guess:
    the paper's statue had texture coordinates]. Blending the *priorities* (not the inked
    colours) keeps the halftone's monotonicity: the inked set still grows as the tone darkens.
    """
    p = as_float_array(position, "position", dtype=np.float64)
    check_shape(p, "position", (None, None, 3))
    n = _normals(normal)
    check_shape(n, "normal", p.shape)
    m = _mask(mask, n)
    s = as_real(spacing, "spacing", lo=0.0, lo_open=True)
    a1 = np.radians(as_real(angle, "angle"))
    a2 = np.radians(as_real(cross_angle, "cross_angle"))
    t1 = as_real(first, "first", lo=0.0, hi=1.0, lo_open=True)
    t2 = as_real(cross, "cross", lo=0.0, hi=1.0, lo_open=True)
    k = as_real(sharpness, "sharpness", lo=0.0, hi=64.0)
    pm = np.where(m[..., None], p, 0.0)
    if not np.all(np.isfinite(pm)):
        raise ValueError("position must be finite on the masked pixels")
    w = np.abs(np.where(m[..., None], n, 0.0)) ** k
    total = w.sum(axis=2, keepdims=True)
    w = np.where(total > 0, w / np.where(total > 0, total, 1.0), 1.0 / 3.0)
    t = (w[..., 0] * _priority(pm[..., 1], pm[..., 2], s, a1, a2, t1, t2)
         + w[..., 1] * _priority(pm[..., 2], pm[..., 0], s, a1, a2, t1, t2)
         + w[..., 2] * _priority(pm[..., 0], pm[..., 1], s, a1, a2, t1, t2))
    return np.where(m, t, 1.0).astype(np.float32)


def object_space(fb):
    """Object-space position and unit normal of the visible surface of a framebuffer.

    Returns
    -------
    position, normal : (H, W, 3) float64
        Positions are the draw call's vertices interpolated with the perspective-correct
        barycentrics; normals are the framebuffer's eye-space normals taken back through each
        draw call's normal matrix (``n_obj ∝ (view·model)ᵀ n_eye``). 0 in the background.
    """
    if not hasattr(fb, "meshes") or fb.meshes is None:
        raise TypeError("fb must be a refraster.Framebuffer that carries its meshes")
    position = fb.interpolate([mm.vertices for mm in fb.meshes])
    normal = np.zeros(position.shape)
    obj = np.asarray(fb.object_id)
    n_eye = np.asarray(fb.normal, np.float64)
    for k, model in enumerate(fb.models):
        sel = obj == k
        if not sel.any():
            continue
        mv = (np.asarray(fb.view) @ np.asarray(model))[:3, :3]
        nk = n_eye[sel] @ mv             # row vectors: (mvᵀ n)ᵀ = nᵀ mv
        length = np.linalg.norm(nk, axis=1, keepdims=True)
        normal[sel] = np.where(length > 0, nk / np.where(length > 0, length, 1.0), 0.0)
    return position, normal


def surface_strokes(fb, *, spacing=None, angle=45.0, cross_angle=-45.0, first=0.9, cross=0.5,
                    sharpness=8.0):
    """:func:`triplanar_strokes` of a framebuffer's visible surface (:func:`object_space`).

    Parameters
    ----------
    fb : refraster.Framebuffer
        A render that carries its meshes; its covered pixels (``fb.mask``) are textured.
    spacing : float > 0, optional
        Distance between strokes of one family, in object units; default 1/60 of the largest
        object-space bounding-box diagonal of the framebuffer's meshes.
    angle, cross_angle, first, cross, sharpness : float
        As :func:`triplanar_strokes` (the same defaults).

    Returns
    -------
    (H, W) float32
        The stroke priority; 1 (paper) outside ``fb.mask``.
    """
    position, normal = object_space(fb)
    if spacing is None:
        diag = max((float(np.linalg.norm(np.ptp(mm.vertices, axis=0))) for mm in fb.meshes
                    if mm.n_vertices), default=1.0)
        spacing = (diag if diag > 0 else 1.0) / 60.0
    return triplanar_strokes(position, normal, spacing=spacing, angle=angle,
                             cross_angle=cross_angle, first=first, cross=cross,
                             sharpness=sharpness, mask=fb.mask)


def smooth_threshold(tone, threshold, *, softness=0.1):
    """Freudenberg et al.'s smooth threshold: paper (1) where the tone exceeds the threshold.

    Parameters
    ----------
    tone, threshold : float arrays of one shape (or broadcastable)
    softness : float >= 0
        Width ``ε`` of the ramp; 0 gives the hard step ``tone > threshold``.

    Returns
    -------
    float32 array
        ``clamp((tone − threshold)/ε + ½, 0, 1)``: 1 = paper, 0 = ink, a linear ramp of width
        ``ε`` around the threshold, which anti-aliases stroke borders.

    Notes
    -----
    Freudenberg, Masuch & Strothotte, "Real-Time Halftoning", EGWR 2002 (the paper's [Fre02a]):
    a hard threshold of a halftone screen aliases, a ramp of a few grey levels does not. The
    ramp's exact form is not in the papers we have; this linear one is a guess.
    """
    i = as_float_array(tone, "tone")
    t = as_float_array(threshold, "threshold")
    eps = as_real(softness, "softness", lo=0.0)
    try:
        diff = i - t
    except ValueError:
        raise ValueError(f"tone {i.shape} and threshold {t.shape} do not broadcast") from None
    if eps == 0.0:
        return (diff > 0.0).astype(np.float32)
    # a tiny (even subnormal) ramp overflows to ±inf, which the clamp turns into the hard step
    with np.errstate(over="ignore"):
        return np.clip(diff / eps + 0.5, 0.0, 1.0).astype(np.float32)


def hatching(normal, *, light=DEFAULT_LIGHT, strokes=None, softness=0.1, ambient=0.15,
             ink=(0.0, 0.0, 0.0), paper=(1.0, 1.0, 1.0), mask=None):
    """Hatching: the diffuse tone halftoned against a prioritized stroke texture.

    Parameters
    ----------
    normal : (H, W, 3) float
    light : (3,) float
    strokes : (H, W) float, optional
        The threshold map; default :func:`stroke_texture` with its defaults.
    softness : float >= 0
        :func:`smooth_threshold`'s ramp width.
    ambient : float in [0, 1]
        Tone of unlit surfaces: ``I = ambient + (1 − ambient)·max(n·l, 0)``.
    ink, paper : (3,) float
    mask : (H, W) bool, optional
        Background pixels are paper.

    Returns
    -------
    (H, W, 3) float32

    Notes
    -----
    Nienhaus & Döllner Sec. 5.2, a per-fragment operation, hence straightforward to combine with
    the edge map (their Fig. 8).
    """
    n = _normals(normal)
    m = _mask(mask, n)
    h, w = n.shape[:2]
    if strokes is None:
        strokes = stroke_texture(h, w)
    st = as_float_array(strokes, "strokes")
    check_shape(st, "strokes", (h, w))
    amb = as_real(ambient, "ambient", lo=0.0, hi=1.0)
    tone = amb + (1.0 - amb) * np.maximum(n @ _light(light), 0.0)
    white = smooth_threshold(tone, st, softness=softness).astype(np.float64)[..., None]
    ink_c, paper_c = _color(ink, "ink"), _color(paper, "paper")
    return _finish(white * paper_c + (1.0 - white) * ink_c, m, paper_c)


def composite(shade, edge_map, *, inner_color=(1.0, 1.0, 1.0), profile_color=(0.0, 0.0, 0.0),
              mask=None):
    """Blend the edge map over a shaded image (the paper's fragment shading, Sec. 5.1).

    Parameters
    ----------
    shade : (H, W, 3) float
        Any style's colour.
    edge_map : (H, W, 4) float in [0, 1]
        :func:`refraster.edges.edge_map`: inner strength in RGB, profile strength in A.
    inner_color, profile_color : (3,) float
        White and black in the paper.
    mask : (H, W) bool, optional
        Composite only these pixels, as the paper's projective texturing onto the objects does
        (the half of each profile line that falls on the background is then lost); default all.

    Returns
    -------
    (H, W, 3) float32
        ``inner = (1 − E_N)·shade + E_N·inner_color``; ``(1 − E_Z)·inner + E_Z·profile_color``.

    Notes
    -----
    MATH.md §3.1 (the printed operators are 1 for no edge, so the paper's "interpolate by the
    intensity" reads ``I·shade + (1 − I)·edge colour``) and §3.2 (with ``E = 1 − I`` as here).
    """
    s = as_float_array(shade, "shade")
    check_shape(s, "shade", (None, None, 3))
    e = as_float_array(edge_map, "edge_map")
    check_shape(e, "edge_map", s.shape[:2] + (4,))
    if e.size and (e.min() < 0.0 or e.max() > 1.0):
        raise ValueError("edge_map strengths must lie in [0, 1]")
    ci, cp = _color(inner_color, "inner_color"), _color(profile_color, "profile_color")
    e_n, e_z = e[..., :3], e[..., 3:4]
    inner = (1.0 - e_n) * s + e_n * ci
    out = (1.0 - e_z) * inner + e_z * cp
    if mask is not None:
        m = np.asarray(mask)
        if m.dtype != np.bool_:
            raise TypeError(f"mask must be a bool array, got dtype {m.dtype}")
        check_shape(m, "mask", s.shape[:2])
        out = np.where(m[..., None], out, s)
    return out.astype(np.float32)


# ------------------------------------------------------------------------------------------
# Mirroring with edge enhancement (Sec. 5.3)


def reflection(point, normal):
    """The 4×4 reflection through the plane with ``point`` and ``normal`` (world space):
    ``X' = X − 2 ((X − P)·n̂) n̂``. It is its own inverse and has determinant −1."""
    p = as_float_array(point, "point", shape=(3,))
    n = as_float_array(normal, "normal", shape=(3,))
    length = float(np.linalg.norm(n))
    if length == 0.0:
        raise ValueError("normal must be a non-zero vector")
    n = n / length
    m = np.eye(4)
    m[:3, :3] -= 2.0 * np.outer(n, n)
    m[:3, 3] = 2.0 * float(p @ n) * n
    return m


@dataclass(frozen=True)
class MirrorStyle:
    """How :func:`render_mirrored` draws the mirror and the edges of both passes (a value).

    Attributes
    ----------
    reflectance : float in [0, 1]
        Mirror pixels are ``reflectance·mirrored + (1 − reflectance)·mirror_color``.
    mirror_color : (3,) float in [0, 1]
        Also the colour where the mirror reflects nothing.
    inner_color, profile_color : (3,) float in [0, 1]
        The edge colours of both passes (:func:`composite`); the mirror's own outline is drawn
        over the reflection in ``profile_color``.

    The values are checked when the style is made (``ValueError``/``TypeError`` naming the
    field) and kept as a float and tuples of floats.
    """

    reflectance: float = 0.85
    mirror_color: tuple = (0.85, 0.88, 0.92)
    inner_color: tuple = (1.0, 1.0, 1.0)
    profile_color: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "reflectance",
                           as_real(self.reflectance, "reflectance", lo=0.0, hi=1.0))
        for name in ("mirror_color", "inner_color", "profile_color"):
            object.__setattr__(self, name,
                               tuple(float(c) for c in _color(getattr(self, name), name)))


@dataclass(frozen=True, eq=False)
class MirrorRender:
    """What :func:`render_mirrored` returns.

    Attributes
    ----------
    image : (H, W, 3) float32
        The final picture: the scene with its edge map, and inside the visible mirror the
        mirrored scene with *its own* edge map.
    scene, mirrored : refraster.Framebuffer
        The scene pass (objects and the mirror, the mirror as the last draw call) and the
        mirrored pass (the objects reflected through the mirror plane, fragments behind the
        plane discarded).
    scene_edges, mirrored_edges : (H, W, 4) float32
        Their edge maps (:func:`refraster.edges.edge_map`).
    mirror_mask : (H, W) bool
        Pixels where the mirror is visible (the paper's stencil).
    plane : (point, normal)
    """

    image: np.ndarray
    scene: object
    mirrored: object
    scene_edges: np.ndarray
    mirrored_edges: np.ndarray
    mirror_mask: np.ndarray
    plane: tuple


def _default_style(fb, light):
    return gooch(fb.normal, light=light, mask=fb.mask)


def render_mirrored(meshes, mirror, *, view, proj, width, height, models=None, style=None,
                    light=DEFAULT_LIGHT, raster=None, mirror_style=MirrorStyle(),
                    edge_options=None, background=(1.0, 1.0, 1.0)):
    """An edge-enhanced scene with a planar mirror (Nienhaus & Döllner Sec. 5.3, Fig. 8).

    Parameters
    ----------
    meshes : mesh or sequence of meshes
        The objects (on the mirror's front side, where its normal points).
    mirror : mesh
        The mirror surface: planar triangles (e.g. a quad); its first face's front normal (the
        counter-clockwise one, the clockwise one under ``raster.front_face="cw"``) is the
        mirror's front.
    view, proj, width, height
        The camera.
    models : list of (4, 4), optional
        One model matrix per object (identity by default); the mirror is not transformed.
    style : callable, optional
        ``style(fb, light) -> (H, W, 3)`` shade of a framebuffer with an eye-space light
        direction (default: :func:`gooch`). For hatching attached to the surface:
        ``lambda fb, l: hatching(fb.normal, light=l, strokes=surface_strokes(fb),
        mask=fb.mask)``.
    light : (3,) float
        Towards the light, in the scene pass's eye space. The mirrored pass uses the same
        world-space light reflected through the plane, so a mirrored surface is lit as the
        surface it mirrors.
    raster : RasterState, optional
        The fixed-function state of both passes (:class:`refraster.RasterState`); None: the
        default state with ``normals="smooth"`` (the paper needs per-vertex normals: a mesh's
        own, given as ``(vertices, faces, normals)``, or area-weighted ones). Its depth test,
        front face and API conventions apply to both passes (the edges are found from eye
        depth, which no convention changes); the depth test must have a direction
        (``less``/``lequal`` cleared to 1, or ``greater``/``gequal`` cleared to 0: reversed-Z),
        depth writes on; anything else is refused with one line naming the field.
    mirror_style : MirrorStyle
        The mirror's reflectance and colour and the edge colours (default: ``MirrorStyle()``,
        reflectance 0.85, a light grey-blue mirror, white inner and black profile edges).
    edge_options : dict, optional
        Keyword arguments of :func:`refraster.edges.edge_map` for both passes (default: the
        paper's operator).
    background : (3,) float

    Returns
    -------
    MirrorRender

    Notes
    -----
    The paper masks the mirror with the stencil buffer and renders two passes, "one for the
    scene without mirror and one for the mirror", applying edge enhancement to each: "the
    scene is rendered from different viewpoints and, hence, the edges are detected
    correctly". Here the mirrored pass draws every object with model ``R·M`` (R the
    reflection, so the camera is unchanged and eye depths are those seen through the mirror)
    and discards fragments on the mirror's front side (objects behind the mirror must not
    appear in it, the job of a user clip plane on a GPU). Its G-buffer fits its own near/far.
    Reflection flips the winding; faces are not culled.
    """
    from . import operators as _edges
    from ..framebuffer import render
    from ..mesh import as_mesh, as_meshes, face_normals
    from ..raster.state import RasterState, require_depth_direction

    state = RasterState(normals="smooth") if raster is None else raster
    if not isinstance(state, RasterState):
        raise TypeError(f"raster must be a refraster.RasterState (or None), got "
                        f"{type(state).__name__}")
    require_depth_direction(state, "render_mirrored")
    objs = as_meshes(meshes)
    mir = as_mesh(mirror, "mirror")
    if mir.n_faces == 0:
        raise ValueError("mirror has no faces")
    if models is None:
        models = [np.eye(4)] * len(objs)
    models = [as_float_array(m, f"models[{k}]", shape=(4, 4)) for k, m in enumerate(models)]
    if len(models) != len(objs):
        raise ValueError(f"models must have one matrix per mesh ({len(objs)}), got {len(models)}")
    fn = face_normals(mir.vertices, mir.faces)
    good = np.flatnonzero(np.any(fn != 0.0, axis=1))
    if good.size == 0:
        raise ValueError("mirror faces are all degenerate")
    normal = fn[good[0]]
    if state.front_face == "cw":   # the front as the state defines it
        normal = -normal
    point = mir.vertices[mir.faces[good[0], 0]]
    size = float(np.linalg.norm(np.ptp(mir.vertices, axis=0)))
    if np.abs((mir.vertices - point) @ normal).max() > 1e-9 * max(size, 1.0):
        raise ValueError("mirror must be planar")
    refl = reflection(point, normal)
    if not isinstance(mirror_style, MirrorStyle):
        raise TypeError(f"mirror_style must be a MirrorStyle, got {type(mirror_style).__name__}")
    rho = mirror_style.reflectance
    mcol = _color(mirror_style.mirror_color, "mirror_color")
    inner_color, profile_color = mirror_style.inner_color, mirror_style.profile_color
    bg = _color(background, "background")
    lt = _light(light)
    style = _default_style if style is None else style
    if not callable(style):
        raise TypeError("style must be callable: (fb, light) -> (H, W, 3)")
    opts = dict(edge_options or {})
    cam = dict(view=view, proj=proj, width=width, height=height)

    # pass 1: the scene with the mirror (last draw call); the mirror's pixels are the stencil
    scene = render(objs + [mir], **cam, model=models + [np.eye(4)], raster=state, background=bg)
    mirror_mask = scene.object_id == len(objs)
    scene_edges = _edges.edge_map(scene, **opts)
    shade = np.asarray(style(scene, lt), np.float64)
    shade[mirror_mask] = mcol
    image = composite(shade, scene_edges, inner_color=inner_color, profile_color=profile_color)

    # pass 2: the objects reflected through the mirror plane, clipped at the plane
    v = np.asarray(view, np.float64)
    light_world = np.linalg.solve(v[:3, :3], lt)
    light_mirrored = v[:3, :3] @ (refl[:3, :3] @ light_world)
    plane = np.append(normal, -float(normal @ point))

    def behind_mirror(frags):
        pos = frags.world_position()
        return pos @ plane[:3] + plane[3] <= 0.0

    mirrored = render(objs, **cam, model=[refl @ m for m in models], raster=state,
                      fragment_stage=behind_mirror, background=bg)
    mirrored_edges = _edges.edge_map(mirrored, **opts) if mirrored.mask.any() else \
        np.zeros((height, width, 4), np.float32)
    m_shade = np.asarray(style(mirrored, light_mirrored), np.float64)
    m_shade[~mirrored.mask] = mcol
    m_image = composite(m_shade, mirrored_edges, inner_color=inner_color,
                        profile_color=profile_color).astype(np.float64)
    in_mirror = rho * m_image + (1.0 - rho) * mcol
    # the mirror's own outline (scene edges) stays drawn over the reflection
    e_z = scene_edges[..., 3:4].astype(np.float64)
    in_mirror = (1.0 - e_z) * in_mirror + e_z * _color(profile_color, "profile_color")
    out = np.where(mirror_mask[..., None], in_mirror, image)
    return MirrorRender(image=out.astype(np.float32), scene=scene, mirrored=mirrored,
                        scene_edges=scene_edges, mirrored_edges=mirrored_edges,
                        mirror_mask=mirror_mask, plane=(point, normal))
