"""The raster state: the fixed-function settings of a GPU pipeline, as one immutable value.

A WebGPU render pipeline is built from one descriptor whose groups are plain records
(``primitive``: cull mode, front face; ``depthStencil``: depth compare, depth write); a draw
call does not repeat them. refraster does the same: :func:`refraster.render`,
:func:`refraster.draw`, :func:`refraster.rasterize`, :func:`refraster.resolve`, the depth
peeler and every technique take one :class:`RasterState` (``raster=``), and the golden scene
packages store its fields (``scene.json``'s ``"raster"``). A new convention (depth range,
window origin, sample count, ...) is a new field here, not a new keyword of every function.

The defaults are OpenGL's (and llvmpipe's): ``less`` with the depth buffer cleared to 1,
depth writes on, no culling, counter-clockwise front faces, 8 sub-pixel bits, llvmpipe's fill
rule, a float32 vertex stage, flat normals, clip space −w ≤ z ≤ w with window depth
``0.5·z/w + 0.5``, a lower-left window origin, NDC y up, no depth clamp and a float32 depth
buffer. The API conventions (``depth_range``, ``origin``, ``ndc_y``, ``depth_clamp``,
``depth_format``) are written down in ``docs/architecture.md``, "Conventions".
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass

import numpy as np

__all__ = ["RasterState", "as_raster_state", "DEPTH_FUNC_NAMES", "CULL_MODES", "FRONT_FACES",
           "FILL_RULE_NAMES", "PRECISIONS", "NORMALS_MODES", "SUBPIXEL_BITS", "DEPTH_RANGES",
           "ORIGINS", "NDC_Y", "DEPTH_FORMATS", "SAMPLE_COUNTS", "SAMPLE_PATTERNS",
           "INTERPOLATIONS", "DIRECTED_DEPTH_FUNCS"]

#: OpenGL's eight depth functions (``glDepthFunc``), comparing the incoming fragment's depth
#: against the stored one.
DEPTH_FUNC_NAMES = ("never", "less", "equal", "lequal", "greater", "notequal", "gequal",
                    "always")
CULL_MODES = ("none", "back", "front")
FRONT_FACES = ("ccw", "cw")
FILL_RULE_NAMES = ("llvmpipe", "bottom-left", "top-left")
PRECISIONS = ("float32", "float64")
NORMALS_MODES = ("flat", "smooth")
SUBPIXEL_BITS = (4, 8)
#: Clip-space depth range (``glClipControl``'s depth mode): −w ≤ z ≤ w with window depth
#: ``0.5·z/w + 0.5`` (OpenGL), or 0 ≤ z ≤ w with window depth ``z/w`` (Vulkan, Direct3D,
#: Metal, WebGPU; OpenGL with ``GL_ZERO_TO_ONE``).
DEPTH_RANGES = ("negative_one_to_one", "zero_to_one")
#: Where the window's y = 0 row lies: at the bottom of the picture (OpenGL) or at its top
#: (Vulkan, Direct3D, Metal, WebGPU; OpenGL with ``GL_UPPER_LEFT``).
ORIGINS = ("lower_left", "upper_left")
#: Which way NDC +y points in the picture: up (OpenGL, Direct3D, Metal, WebGPU) or down
#: (Vulkan).
NDC_Y = ("up", "down")
#: The depth buffer a candidate renders into (refraster's own output stays float32).
DEPTH_FORMATS = ("float32", "unorm24", "unorm16")
#: Samples per pixel (``VkSampleCountFlagBits`` 1 to 16; ``docs/multisample.md``).
SAMPLE_COUNTS = (1, 2, 4, 8, 16)
#: Named sample patterns: Vulkan's standard sample locations (the same as Direct3D's), and the
#: 4× pattern llvmpipe rasterizes with under OpenGL (``refraster.raster.samples``).
SAMPLE_PATTERNS = ("standard", "gl_llvmpipe")
#: Where a multisampled fragment's attributes are interpolated.
INTERPOLATIONS = ("center", "centroid", "sample")


def _sample_locations(value, samples):
    """A named pattern (lower-cased) or user positions as a tuple of ``(x, y)`` int pairs."""
    if isinstance(value, str):
        key = _choice(value, "sample_locations", SAMPLE_PATTERNS)
        if key == "gl_llvmpipe" and samples != 4:
            raise ValueError(f"raster.sample_locations='gl_llvmpipe' is llvmpipe's 4x pattern; "
                             f"raster.samples must be 4 for it, got {samples}")
        return key
    try:
        pairs = tuple(tuple(p) for p in value)
    except TypeError:
        raise TypeError(f"raster.sample_locations must be one of {', '.join(SAMPLE_PATTERNS)} "
                        f"or a sequence of (x, y) pairs in 1/16 pixel, got "
                        f"{type(value).__name__}") from None
    if len(pairs) != samples:
        raise ValueError(f"raster.sample_locations must give one (x, y) pair per sample "
                         f"({samples}), got {len(pairs)}")
    out = []
    for i, p in enumerate(pairs):
        if len(p) != 2 or any(isinstance(c, (bool, np.bool_))
                              or not isinstance(c, numbers.Integral) for c in p):
            raise TypeError(f"raster.sample_locations[{i}] must be a pair of ints (x, y) in "
                            f"1/16 pixel, got {p!r}")
        if not all(0 <= int(c) <= 15 for c in p):
            raise ValueError(f"raster.sample_locations[{i}] must lie in 0..15 (1/16 pixel from "
                             f"the pixel's upper-left corner, as VK_EXT_sample_locations), "
                             f"got {p!r}")
        out.append((int(p[0]), int(p[1])))
    return tuple(out)


def _choice(value, field, choices):
    if not isinstance(value, str):
        raise TypeError(f"raster.{field} must be a string, one of {', '.join(choices)}; "
                        f"got {type(value).__name__}")
    key = value.lower()
    if key not in choices:
        raise ValueError(f"raster.{field} must be one of {', '.join(choices)}; got {value!r}")
    return key


@dataclass(frozen=True)
class RasterState:
    """The fixed-function state a frame is rasterized with (immutable; compare with ``==``).

    Parameters
    ----------
    depth_func : {"less", "lequal", "greater", "gequal", "equal", "notequal", "always", "never"}
        The depth test (``glDepthFunc``), incoming fragment against the stored depth; ties go
        to the first fragment drawn, as in OpenGL.
    depth_write : bool
        Whether a fragment that passes writes its depth (``glDepthMask``). False is supported
        by :func:`refraster.resolve` and by ``render`` (which then resolves the fragment
        stream instead of running the fused tile pass).
    clear_depth : float in [0, 1]
        The depth buffer's clear value (``glClearDepth``).
    cull : {"none", "back", "front"}
        Face culling (``glCullFace``), by the facing :attr:`front_face` defines.
    front_face : {"ccw", "cw"}
        Which winding, as the picture is seen (row 0 at the top, whatever the origin and NDC
        y), is the front (``glFrontFace``, ``VkFrontFace``, D3D's ``FrontCounterClockwise``).
        ``"cw"`` renders exactly what ``"ccw"`` renders of the same mesh with every face's
        winding reversed, except for the facing-dependent order of the barycentrics' vertices
        (a face's barycentrics always refer to its own vertices 0, 1, 2).
    subpixel_bits : {8, 4}
        Fixed-point snapping of window positions (8: llvmpipe and current desktop GPUs; 4:
        OpenGL's minimum).
    fill_rule : {"llvmpipe", "bottom-left", "top-left"}
        Which triangle owns a pixel centre exactly on a shared edge, as the picture is seen:
        ``"llvmpipe"`` (alias ``"bottom-left"``) owns left edges and horizontal edges at the
        bottom of the triangle (llvmpipe under OpenGL's lower-left origin: the edges of
        smallest window y); ``"top-left"`` owns left edges and horizontal edges at the top —
        Direct3D's rule exactly as it defines it in its upper-left render-target coordinates
        (a top edge is horizontal and above the other edges: smallest y there, largest y in
        GL's lower-left coordinates). The rule does not change meaning with ``origin``.
    precision : {"float32", "float64"}
        Vertex-stage arithmetic (float32 as a GPU's vertex shader).
    normals : {"flat", "smooth"}
        G-buffer normals: the face normal, or per-vertex normals interpolated perspective-
        correctly and renormalized — a mesh's own (``Mesh.vertex_normals``, or the third
        element of a ``(vertices, faces, normals)`` triple) where it has them, else
        area-weighted ones (:func:`refraster.mesh.smooth_normals`).
    depth_range : {"negative_one_to_one", "zero_to_one"}
        The clip volume's depth and the window depth: −w ≤ z ≤ w and ``0.5·z/w + 0.5``
        (OpenGL), or 0 ≤ z ≤ w and ``z/w`` (Vulkan, Direct3D, Metal, WebGPU).
    origin : {"lower_left", "upper_left"}
        The window origin (``glClipControl``'s origin): window y counts up from the bottom
        of the picture (OpenGL) or down from its top (the others). Images are always
        returned with row 0 at the top of the picture. Window positions are snapped in the
        API's own window coordinates.
    ndc_y : {"up", "down"}
        Which way NDC +y points in the picture (``"down"``: Vulkan). The same clip
        coordinates under ``"down"`` give the picture mirrored top to bottom, so every
        face's winding as seen is reversed.
    depth_clamp : bool
        No clipping against the near and far planes; each fragment's depth is clamped to
        [0, 1] (``GL_DEPTH_CLAMP``, Vulkan's ``depthClampEnable`` with depth clipping off,
        WebGPU's ``unclippedDepth``). Clipping against w > 0 still removes what lies at or
        behind the eye.
    depth_format : {"float32", "unorm24", "unorm16"}
        The candidate's depth buffer (its quantisation is part of the golden allowance; the
        GL and wgpu backends render into it). refraster's own depth output stays float32.
    samples : {1, 2, 4, 8, 16}
        Samples per pixel (``rasterizationSamples``). 1 is the single-sample pipeline; more
        are rendered by :func:`refraster.render_samples` (``docs/multisample.md``).
    sample_locations : {"standard", "gl_llvmpipe"} or sequence of (x, y) int pairs
        Where the samples lie in a pixel: Vulkan's standard sample locations (Direct3D's
        too), llvmpipe's 4× pattern under OpenGL (``samples=4`` only), or one ``(x, y)`` per
        sample in 1/16 pixel, 0..15, from the pixel's upper-left corner as the picture is
        seen, x right and y down (``VK_EXT_sample_locations``' grid).
    interpolation : {"center", "centroid", "sample"}
        Where a multisampled fragment's attributes (barycentrics, so normals and colour) are
        interpolated: the pixel centre, a centroid point (the centre when the primitive covers
        every sample, else its covered sample nearest the centre) or each sample's own
        position (sample shading). One sample per pixel: all three are the centre.

    Front faces, the fill rule and the window origin are defined as the picture is seen
    (row 0 at the top): ``front_face="ccw"`` is counter-clockwise on screen for every
    origin and NDC direction (as OpenGL — which negates the area under ``GL_UPPER_LEFT`` —
    Vulkan, Direct3D and WebGPU define it), and ``"top-left"`` owns the edges at the top of
    the picture (Direct3D's rule, in its upper-left window coordinates).

    Examples
    --------
    >>> from refraster import RasterState
    >>> reversed_z = RasterState(depth_func="greater", clear_depth=0.0,
    ...                          depth_range="zero_to_one")
    >>> reversed_z.replace(cull="back").cull
    'back'
    """

    depth_func: str = "less"
    depth_write: bool = True
    clear_depth: float = 1.0
    cull: str = "none"
    front_face: str = "ccw"
    subpixel_bits: int = 8
    fill_rule: str = "llvmpipe"
    precision: str = "float32"
    normals: str = "flat"
    depth_range: str = "negative_one_to_one"
    origin: str = "lower_left"
    ndc_y: str = "up"
    depth_clamp: bool = False
    depth_format: str = "float32"
    samples: int = 1
    sample_locations: object = "standard"
    interpolation: str = "center"

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        put("depth_func", _choice(self.depth_func, "depth_func", DEPTH_FUNC_NAMES))
        if not isinstance(self.depth_write, (bool, np.bool_)):
            raise TypeError(f"raster.depth_write must be a bool, got "
                            f"{type(self.depth_write).__name__}")
        put("depth_write", bool(self.depth_write))
        cd = self.clear_depth
        if isinstance(cd, bool) or not isinstance(cd, numbers.Real):
            raise TypeError(f"raster.clear_depth must be a number, got {type(cd).__name__}")
        cd = float(cd)
        if not 0.0 <= cd <= 1.0:   # also refuses NaN
            raise ValueError(f"raster.clear_depth must lie in [0, 1], got {cd!r}")
        put("clear_depth", cd)
        put("cull", _choice(self.cull, "cull", CULL_MODES))
        put("front_face", _choice(self.front_face, "front_face", FRONT_FACES))
        bits = self.subpixel_bits
        if isinstance(bits, bool) or not isinstance(bits, numbers.Integral):
            raise TypeError(f"raster.subpixel_bits must be an int, got {type(bits).__name__}")
        if int(bits) not in SUBPIXEL_BITS:
            raise ValueError(f"raster.subpixel_bits must be 4 or 8, got {bits}")
        put("subpixel_bits", int(bits))
        put("fill_rule", _choice(self.fill_rule, "fill_rule", FILL_RULE_NAMES))
        put("precision", _choice(self.precision, "precision", PRECISIONS))
        put("normals", _choice(self.normals, "normals", NORMALS_MODES))
        put("depth_range", _choice(self.depth_range, "depth_range", DEPTH_RANGES))
        put("origin", _choice(self.origin, "origin", ORIGINS))
        put("ndc_y", _choice(self.ndc_y, "ndc_y", NDC_Y))
        if not isinstance(self.depth_clamp, (bool, np.bool_)):
            raise TypeError(f"raster.depth_clamp must be a bool, got "
                            f"{type(self.depth_clamp).__name__}")
        put("depth_clamp", bool(self.depth_clamp))
        put("depth_format", _choice(self.depth_format, "depth_format", DEPTH_FORMATS))
        n = self.samples
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, numbers.Integral):
            raise TypeError(f"raster.samples must be an int, got {type(n).__name__}")
        if int(n) not in SAMPLE_COUNTS:
            raise ValueError(f"raster.samples must be one of 1, 2, 4, 8, 16, got {n}")
        put("samples", int(n))
        put("sample_locations", _sample_locations(self.sample_locations, int(n)))
        put("interpolation", _choice(self.interpolation, "interpolation", INTERPOLATIONS))

    @property
    def shading_rate(self):
        """``"sample"`` when ``interpolation == "sample"``, else ``"pixel"``: how often a
        technique's fragment stage (a clip surface's discard, the parity test) runs at
        ``samples > 1``. At pixel rate it runs once per fragment — one triangle in one pixel —
        at the centre or centroid, and its discard removes every sample the fragment covers;
        at sample rate once per covered sample at the sample's position. The GPU mechanism is
        the same: an input interpolated at the sample (GLSL's ``sample`` qualifier,
        ``gl_SampleID``/``SV_SampleIndex`` read, or ``GL_SAMPLE_SHADING``/Vulkan's
        ``sampleShadingEnable`` with a minimum fraction of 1.0) makes the shader run per
        sample."""
        return "sample" if self.interpolation == "sample" else "pixel"

    def replace(self, **changes):
        """A copy with some fields changed (validated like a new value)."""
        return dataclasses.replace(self, **changes)

    def as_dict(self):
        """The fields as a plain dict (JSON types), in declaration order."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        if not isinstance(self.sample_locations, str):
            out["sample_locations"] = [list(p) for p in self.sample_locations]
        return out

    @classmethod
    def from_dict(cls, fields, *, name="raster"):
        """A state from a mapping of field names (unknown names refused with one line)."""
        if not isinstance(fields, dict):
            raise TypeError(f"{name} must be a mapping of raster state fields, got "
                            f"{type(fields).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(fields) - known)
        if unknown:
            raise ValueError(f"{name} has unknown field(s) {', '.join(map(repr, unknown))}; "
                             f"known: {', '.join(sorted(known))}")
        return cls(**fields)


#: The default state (OpenGL's), shared so that the common call builds nothing.
DEFAULT = RasterState()


def as_raster_state(raster, name="raster"):
    """``None`` → the default state; a :class:`RasterState` as it is; anything else refused."""
    if raster is None:
        return DEFAULT
    if isinstance(raster, RasterState):
        return raster
    raise TypeError(f"{name} must be a refraster.RasterState (or None for the default), got "
                    f"{type(raster).__name__}; e.g. raster=RasterState(depth_func='lequal')")


def require_single_sample(state, where):
    """Refuse, with one line, a multisample state where only one sample per pixel is made
    (the single-sample pipeline and the techniques); :func:`refraster.render_samples` makes
    the samples."""
    if state.samples != 1 or state.sample_locations != "standard":
        raise ValueError(f"raster.samples must be 1 with sample_locations 'standard' for "
                         f"{where} (one sample at the pixel centre), got samples="
                         f"{state.samples}, sample_locations={state.sample_locations!r}; "
                         f"refraster.render_samples renders multisampled frames")
    return state


def require_default(state, fields, where):
    """Refuse, with one line, a state whose ``fields`` differ from the default: for a technique
    that does not honour them (yet), a silent default would be a wrong picture. A multisample
    state is refused too (:func:`require_single_sample`): no technique makes samples."""
    require_single_sample(state, where)
    for f in fields:
        if getattr(state, f) != getattr(DEFAULT, f):
            raise ValueError(f"raster.{f} must be {getattr(DEFAULT, f)!r} for {where} (it "
                             f"follows OpenGL's default there), got {getattr(state, f)!r}")
    return state


#: The depth functions that define a direction (what "nearer" means): ascending depth for
#: ``less``/``lequal`` (OpenGL's default), descending for ``greater``/``gequal`` (reversed-Z).
DIRECTED_DEPTH_FUNCS = ("less", "lequal", "greater", "gequal")


def reverses(state):
    """True when the state's depth test keeps the larger depth (``greater``, ``gequal``:
    reversed-Z): "nearer" is the larger window depth."""
    return state.depth_func in ("greater", "gequal")


def require_depth_direction(state, where, *, multisample=False):
    """Refuse, with one line naming the field, a state whose depth test has no direction for a
    technique that compares depths itself (cut tests, cap depth tests, peeling): the depth
    function must be ``less``/``lequal`` with the buffer cleared to 1 (the far end) or
    ``greater``/``gequal`` (reversed-Z) cleared to 0, with depth writes on. A multisample state
    is refused too (:func:`require_single_sample`) unless the technique renders samples
    (``multisample=True``). The other fields (front face, culling, the API conventions) are the
    technique's to honour."""
    if not multisample:
        require_single_sample(state, where)
    if state.depth_func not in DIRECTED_DEPTH_FUNCS:
        raise ValueError(f"raster.depth_func must be one of {', '.join(DIRECTED_DEPTH_FUNCS)} "
                         f"for {where} (a direction of depth: nearer is smaller or larger), "
                         f"got {state.depth_func!r}")
    far = 0.0 if reverses(state) else 1.0
    if state.clear_depth != far:
        raise ValueError(f"raster.clear_depth must be {far!r} under depth_func="
                         f"{state.depth_func!r} for {where} (the buffer cleared to the far "
                         f"end), got {state.clear_depth!r}")
    if not state.depth_write:
        raise ValueError(f"raster.depth_write must be True for {where} (its passes resolve "
                         f"the nearest fragment), got False")
    return state


def gl_clip_map(state):
    """``T`` (4×4 float64) taking the state's clip coordinates to the equivalent ones in
    OpenGL's conventions (the same picture, window depth ``d`` kept, or ``1 − d`` under a
    reversing depth test): ``y → −y`` under ``ndc_y="down"``, ``z → 2z − w`` under
    ``depth_range="zero_to_one"``, then ``z → −z`` under ``greater``/``gequal``; ``None`` when
    it is the identity (the state speaks OpenGL's dialect). The window origin is no map: images
    are row 0 at the top in every convention. A technique that computes from window depth or
    from the projection (unprojecting pixels, NDC depth slopes) works in these coordinates
    with ``T·proj`` (``docs/architecture.md``, "Conventions")."""
    if state.ndc_y == "up" and state.depth_range == "negative_one_to_one" \
            and not reverses(state):
        return None
    t = np.eye(4)
    if state.ndc_y == "down":
        t[1, 1] = -1.0
    if state.depth_range == "zero_to_one":
        t[2] = (0.0, 0.0, 2.0, -1.0)
    if reverses(state):
        t[2] = -t[2]
    return t
