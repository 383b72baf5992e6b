"""Multisampled G-buffers and their resolve (``docs/multisample.md``).

:func:`render_samples` renders a frame with ``raster.samples`` samples per pixel at
``raster.sample_locations`` into per-sample buffers shaped ``(H, W, S[, C])``;
:func:`resolve_color` and :func:`resolve_samples` turn them into one value per pixel with
Vulkan's resolve modes (``VkResolveModeFlagBits``).
"""

from __future__ import annotations

import numpy as np

from ._scratch import SCRATCH_FACES, scratch_lease
from ._threads import frame_work, threads_for
from ._validate import as_float_array, as_image_size
from .framebuffer import _build
from .mesh import as_meshes
from .raster import _prepare, facing
from .raster.multisample import rasterize_samples, stream_samples
from .raster.rasterizer import MAX_FACES
from .raster.rasterizer import DEPTH_FUNCS
from .raster.samples import sample_offsets, sample_points
from .raster.state import as_raster_state

__all__ = ["SampleFramebuffer", "render_samples", "draw_samples", "sample_image",
           "resolve_color", "resolve_samples", "RESOLVE_MODES"]

#: Vulkan's resolve modes (``VK_RESOLVE_MODE_*``): ``"sample_zero"`` (sample 0's value),
#: ``"average"`` (the box filter; colour and depth, not ids), ``"min"``, ``"max"``.
RESOLVE_MODES = ("sample_zero", "average", "min", "max")


class SampleFramebuffer:
    """A multisampled G-buffer: :class:`refraster.Framebuffer`'s buffers with a sample axis.

    ``depth``, ``eye_depth``, ``prim_id``, ``object_id``, ``front_facing`` are ``(H, W, S)``;
    ``normal``, ``barycentric``, ``color`` ``(H, W, S, 3)`` — sample ``s`` of pixel ``(r, c)``
    at ``[r, c, s]``, row 0 at the top, the samples in the pattern's index order. Each
    sample's values are those of the fragment that won its depth test, its attributes
    interpolated where ``raster.interpolation`` says. ``color`` is shaded when first read, as
    :attr:`refraster.Framebuffer.color`, from the buffers as they are then (with one draw
    call ``prim_id`` is the face image the shade reads: its ids are the call's faces).
    ``positions``: ``(S, 2)`` the samples' positions in pixels from the pixel's upper-left
    corner as the picture is seen, y down; ``raster``: the state it was rendered with.
    """

    __slots__ = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing",
                 "barycentric", "positions", "raster", "_shade", "_color")

    def __init__(self, *, depth, eye_depth, normal, prim_id, object_id, front_facing,
                 barycentric, color, positions, raster=None):
        self.depth, self.eye_depth, self.normal = depth, eye_depth, normal
        self.prim_id, self.object_id, self.front_facing = prim_id, object_id, front_facing
        self.barycentric, self.positions, self.raster = barycentric, positions, raster
        # an array, or a callable giving the (H, W, S, 3) colour when first read
        self._shade, self._color = (color, None) if callable(color) else (None, color)

    @property
    def color(self):
        if self._color is None:
            self._color = self._shade()
            self._shade = None
        return self._color

    @property
    def samples(self):
        return int(self.depth.shape[2])

    @property
    def mask(self):
        """Covered samples, ``(H, W, S)`` bool."""
        return self.prim_id >= 0

    def arrays(self):
        """The per-sample buffers as a dict of arrays."""
        return {k: getattr(self, k) for k in ("depth", "eye_depth", "normal", "prim_id",
                                               "object_id", "front_facing", "barycentric",
                                               "color")}


def render_samples(meshes, *, view, proj, width, height, model=None, raster=None,
                   background=(1.0, 1.0, 1.0)):
    """Render meshes with ``raster.samples`` samples per pixel; returns a
    :class:`SampleFramebuffer`.

    The arguments are :func:`refraster.render`'s. Coverage is the rasterizer's fixed-point
    edge functions and fill rule at each sample position of ``raster.sample_locations``;
    each sample's depth is the depth plane at the sample, tested per sample with
    ``raster.depth_func`` (depth writes on); attributes are interpolated at
    ``raster.interpolation``'s point. ``raster.samples=1`` with the standard pattern gives
    :func:`refraster.render`'s buffers with a sample axis of length 1 (the same bits). At
    most 2³¹ faces over all draw calls (``refraster.raster.rasterizer.MAX_FACES``).
    """
    state = as_raster_state(raster)
    if not state.depth_write:
        raise ValueError("raster.depth_write must be True for render_samples (the per-sample "
                         "depth test keeps the nearest sample)")
    bg = as_float_array(background, "background", shape=(3,))
    meshes = as_meshes(meshes)
    w, h = as_image_size(width, height)
    n_faces = sum(m.n_faces for m in meshes)
    if n_faces > MAX_FACES:
        raise ValueError(f"meshes: {n_faces:,} faces in all; render_samples takes at most "
                         f"{MAX_FACES:,} (its sample face image is int32)")
    # the intermediates (primitive stage, tile lists) in this thread's reused buffers, as
    # render's (none of them is returned or kept; None when a frame of this thread is running)
    with threads_for(frame_work(n_faces, w, h)), \
            scratch_lease(n_faces >= SCRATCH_FACES) as scratch:
        prep = _prepare(meshes, view=view, proj=proj, width=w, height=h, model=model,
                        state=state, scratch=scratch, multisample=True)
        ox, oy = sample_offsets(state)
        depth, prim_global, front, bary = rasterize_samples(
            prep.triangles, ox, oy, fill_rule=prep.fill_rule,
            depth_func=DEPTH_FUNCS[state.depth_func], clear_depth=state.clear_depth,
            interpolation=state.interpolation, scratch=scratch, fill=False)
        s = len(ox)
        facing(state, front, prim_global)
        # the samples as the columns of an (H, W·S) image: the G-buffer's finalize and shade
        # look at each sample's face and barycentrics only, never at its position
        fb = _build(prep.meshes, prep.models, prep.view, prep.proj, depth.reshape(h, w * s),
                    prim_global.reshape(h, w * s), prep.face_offsets,
                    front.reshape(h, w * s), bary.reshape(h, w * s, 3), state.normals, bg,
                    share_ids=True, raster_bg=state.clear_depth)
    return SampleFramebuffer(
        depth=depth, eye_depth=fb.eye_depth.reshape(h, w, s),
        normal=fb.normal.reshape(h, w, s, 3), prim_id=fb.prim_id.reshape(h, w, s),
        object_id=fb.object_id.reshape(h, w, s), front_facing=front,
        barycentric=bary, color=lambda: np.asarray(fb.color).reshape(h, w, s, 3),
        positions=sample_points(state),
        raster=state)


def draw_samples(meshes, *, view, proj, width, height, model=None, raster=None):
    """Draw meshes into a per-sample fragment stream: one fragment per covered sample.

    The arguments are :func:`refraster.draw`'s, with ``raster.samples`` samples per pixel at
    ``raster.sample_locations``. Returns :class:`refraster.Fragments` over the *sample image*
    ``(H, W·S)`` (``frags.width == W·S``): the fragment of sample ``s`` of pixel ``(row, col)``
    has ``pixel = (row·W + col)·S + s``, its own depth (the depth plane at the sample), and
    the barycentrics at ``raster.interpolation``'s point — the pixel centre or centroid
    (shared by all samples one triangle covers in the pixel: a fragment stage evaluated
    there decides at **pixel rate**) or the sample's own position (``"sample"``: **sample
    rate**, ``raster.shading_rate == "sample"``). Within each sample the stream is in draw
    order, so :func:`refraster.resolve` (with :func:`sample_image`'s single-sample state) is
    the per-sample depth test, and with no fragment discarded it gives
    :func:`render_samples`'s buffers bit for bit. A fragment stage over this stream is how
    the techniques run at ``samples > 1`` (``docs/multisample.md``, "Fragment stages per
    sample").
    """
    from .raster import _fragments_from
    state = as_raster_state(raster)
    meshes = as_meshes(meshes)
    w, h = as_image_size(width, height)
    with threads_for(frame_work(sum(m.n_faces for m in meshes), w, h)):
        prep = _prepare(meshes, view=view, proj=proj, width=w, height=h, model=model,
                        state=state, scratch=None, multisample=True)
        ox, oy = sample_offsets(state)
        pixel, depth, prim, front, bary, _ = stream_samples(
            prep.triangles, ox, oy, fill_rule=prep.fill_rule, interpolation=state.interpolation)
    frags = _fragments_from(prep, pixel, depth, prim, front, bary)
    frags.width = w * len(ox)
    return frags


def sample_image(state):
    """The single-sample state that resolves, peels and shades a sample image ``(H, W·S)``
    (:func:`draw_samples`): ``state`` with one sample at the centre. Every other field (the
    depth test, the conventions) is kept."""
    return state.replace(samples=1, sample_locations="standard", interpolation="center")


def _per_sample(values, name):
    a = np.asarray(values)
    if a.ndim < 3:
        raise ValueError(f"{name} must have a sample axis, shape (H, W, S[, C]), got shape "
                         f"{a.shape}")
    return a


def resolve_samples(values, mode="sample_zero"):
    """One value per pixel of a per-sample buffer ``(H, W, S[, C])`` by a Vulkan resolve mode.

    ``"sample_zero"``: sample 0 (Vulkan's only mode every depth format supports);
    ``"min"`` / ``"max"``: the smallest / largest sample (per channel); ``"average"``: the
    box filter in float64, rounded to the input's float type (floats only: Vulkan does not
    average integer formats, so ids are refused). Returns ``(H, W[, C])``.
    """
    a = _per_sample(values, "values")
    if mode not in RESOLVE_MODES:
        raise ValueError(f"mode must be one of {', '.join(RESOLVE_MODES)}, got {mode!r}")
    if mode == "sample_zero":
        return a[:, :, 0].copy()
    if mode == "min":
        return a.min(axis=2)
    if mode == "max":
        return a.max(axis=2)
    if not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"mode 'average' needs a float buffer (Vulkan averages no integer "
                         f"or id format), got {a.dtype}")
    return a.astype(np.float64).mean(axis=2).astype(a.dtype)


def _srgb_decode(c):
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _srgb_encode(c):
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * np.power(np.maximum(c, 0.0031308),
                                                                 1.0 / 2.4) - 0.055)


def resolve_color(color, encoding="linear"):
    """The box-filter resolve of a per-sample colour buffer ``(H, W, S, C)``.

    ``encoding="linear"``: the values are linear, averaged as they are; ``"srgb"``: they are
    sRGB-encoded (an ``*_SRGB`` target, or a picture stored for display), decoded to linear,
    averaged and encoded again, as a GPU resolves an sRGB attachment. float64 inside, returned
    as the input's float type.
    """
    a = _per_sample(color, "color")
    if a.ndim != 4:
        raise ValueError(f"color must be shaped (H, W, S, C), got shape {a.shape}")
    if not np.issubdtype(a.dtype, np.floating):
        raise TypeError(f"color must be a float array, got {a.dtype}")
    if encoding == "linear":
        return a.astype(np.float64).mean(axis=2).astype(a.dtype)
    if encoding == "srgb":
        lin = _srgb_decode(np.clip(a.astype(np.float64), 0.0, 1.0)).mean(axis=2)
        return _srgb_encode(lin).astype(a.dtype)
    raise ValueError(f"encoding must be 'linear' or 'srgb', got {encoding!r}")
