"""Compiling the kernels ahead, and saying so.

refraster's kernels are Numba functions compiled on first use and kept in Numba's on-disk cache
(``cache=True``): a fresh clone, a fresh ``NUMBA_CACHE_DIR`` or a changed source file compiles
them again, which takes minutes for the gallery. This module

* tells which kernels are in the cache (:func:`cache_state`, shown by ``refraster info``),
* reports compiling while it happens (:class:`CompileProgress`: one line, "compiling kernels,
  first run only: k of n", then the time it took), and nothing when the cache is warm,
* compiles ahead (:func:`warm_core` for ``render``; ``refraster warmup`` for everything, e.g.
  in a CI image or a Docker layer).

It stands on the tools floor (docs/architecture.md, "Floors"), with :mod:`refraster._workers`:
above the techniques (it imports them to compile their kernels), below the goldens, the gallery
and the command, which use it; the core and the techniques never import it.
"""

from __future__ import annotations

import importlib
import os
import sys
import threading
import time

from ._tiers import RENDER_KERNELS as _RENDER_KERNELS

__all__ = ["SPLIT_KERNEL", "warm_only", "warm_core_split", "KERNEL_MODULES", "CORE_MODULES", "RENDER_KERNELS", "CLIP_KERNELS", "STREAM_KERNELS", "GALLERY_SKIPS", "kernels", "cache_state", "CompileProgress",
           "warm_core", "compile_listener", "CLIPSURFACE_SIDE_KERNELS", "warm_clipsurface_side",
           "FUSED_CLIP_KERNEL", "warm_fused_clip", "warm_full_tier"]

#: The modules whose kernels the pipeline (``refraster.render``) compiles.
CORE_MODULES = ("refraster.mesh", "refraster.raster.primitive", "refraster.raster.rasterizer",
                "refraster.raster.gbuffer")
#: The kernels ``refraster.render`` compiles for a frame and its colour, flat or smooth, when
#: no face crosses a clipping plane (a mesh framed by the camera), by ``module.qualname``; the
#: rest of the core's are other paths' (clipping: :data:`CLIP_KERNELS`; the fragment stream,
#: float64 vertices, smooth normals with creases).
RENDER_KERNELS = _RENDER_KERNELS
#: The kernels of faces crossing a clipping plane (compiled only when a frame has one).
CLIP_KERNELS = ("refraster.raster.primitive._clip_pass",
                "refraster.raster.primitive._clip_polygon",
                "refraster.raster.primitive._clipped_face",
                "refraster.raster.primitive.count_pieces")
#: ``RENDER_KERNELS``, ``CLIP_KERNELS`` and the fragment-stream path's
#: (``warm_core(clip=True, stream=True, multisample=True)``, what the gallery's sections
#: share).
STREAM_KERNELS = RENDER_KERNELS + CLIP_KERNELS + (
    "refraster.raster.rasterizer._stream_pass", "refraster.raster.fragments._interpolate_kernel",
    "refraster.raster.resolve._resolve")
#: The clip-surface kernels :func:`warm_clipsurface_side` compiles: those that need neither
#: the pipeline's kernels nor a depth-peeled solid to be called (the rest of the clip
#: surfaces' — the fused pass, the cap culling, the exact caps' ray roots — compile where the
#: section first renders).
CLIPSURFACE_SIDE_KERNELS = (
    "refraster.clipsurface.offsetmaps._occlusion_kernel",
    "refraster.clipsurface.offsetmaps._sample_kernel",
    "refraster.clipsurface.capping._cap_pixels_kernel",
    "refraster.clipsurface.surfaces._clip_kernel",
    "refraster.clipsurface.capping._cap_light_kernel",
    "refraster.clipsurface.textures._sample2d_kernel",
    "refraster.clipsurface.textures._sample3d_kernel",
    "refraster.clipsurface.capping._differing_words")
#: Every module that defines kernels, in pipeline order.
KERNEL_MODULES = CORE_MODULES + (
    "refraster.raster.fragments", "refraster.raster.resolve", "refraster.raster.multisample",
    "refraster.ldi",
    "refraster.clipsurface.offsetmaps", "refraster.clipsurface.capping",
    "refraster.clipsurface.surfaces", "refraster.clipsurface.textures",
    "refraster.clipsurface.fused", "refraster.edges.operators", "refraster.edges.npr",
    "refraster.cutaway.flood",
    "refraster.halos4d.thicken", "refraster.halos4d.slicing", "refraster.halos4d.render",
    "refraster.conformance",
    "refraster.golden.allowances.layers", "refraster.golden.allowances.edges")

#: Kernels ``refraster gallery`` never compiles (other options, the goldens' allowances), so
#: that its progress line counts to the number it compiles: the kernels of
#: :data:`KERNEL_MODULES` not among the compile events of a cold gallery run
#: (``python -m benchmarks.cold_start --kernels``, 2026-12-01). A stale entry only makes the
#: count approximate.
GALLERY_SKIPS = (
    "refraster.golden.allowances.edges._absdiff",
    "refraster.golden.allowances.edges._bounds_kernel",
    "refraster.golden.allowances.edges._component_bounds",
    "refraster.golden.allowances.edges._depth_op_kernel",
    "refraster.golden.allowances.edges._diagonals",
    "refraster.golden.allowances.edges._dot_bounds",
    "refraster.golden.allowances.edges._lin",
    "refraster.golden.allowances.edges._mean_bounds_kernel",
    "refraster.golden.allowances.edges._mean_dot_bounds",
    "refraster.golden.allowances.edges._normal_op_kernel",
    "refraster.golden.allowances.edges._npr_kernel",
    "refraster.golden.allowances.edges._sobel_bounds",
    "refraster.golden.allowances.edges._sq",
    "refraster.golden.allowances.edges._store",
    "refraster.golden.allowances.layers._count_bounds",
    "refraster.clipsurface.capping._hatch_kernel",
    "refraster.clipsurface.surfaces._g_kernel",
    "refraster.edges.operators._id_kernel",
    "refraster.edges.operators._sobel_kernel",
    # the slicing's kernels: the fused halo engine slices in its fill pass (issue 46); the
    # reference engine, voxelize and the golden's slicing call them
    "refraster.halos4d.slicing._count_pass",
    "refraster.halos4d.slicing._place",
    "refraster.halos4d.slicing._write_pass",
    "refraster.halos4d.slicing.window_setup",
    "refraster.halos4d.slicing._edge",
    "refraster.halos4d.slicing._face",
    "refraster.halos4d.slicing._sorted3",
    "refraster.halos4d.slicing._voxelize_exact",
    "refraster.halos4d.slicing._voxelize_snapped",
    "refraster.halos4d.slicing.covered",
    "refraster.halos4d.slicing.face_orientation",
    "refraster.halos4d.slicing.inside_tet",
    "refraster.halos4d.slicing.tet_setup",
    "refraster.raster.primitive._transform64",
    "refraster.conformance._mark_edge",
    "refraster.conformance._mark_faces",
    "refraster.conformance._plane_z",
    "refraster.conformance._seg_dist",
    "refraster.conformance._set_pass",
    # a Framebuffer.reusable's span clear (issue 28): `refraster warmup` compiles it
    "refraster.raster.gbuffer.clear_spans",
)

#: The progress line's words (tests look for them).
COMPILING = "compiling kernels, first run only"


def _is_kernel(obj):
    """A refraster kernel (a quick tier's helper twin, compiled into its callers, is not)."""
    from numba.core.registry import CPUDispatcher
    return (isinstance(obj, CPUDispatcher) and obj.py_func.__module__.startswith("refraster.")
            and not obj.py_func.__qualname__.endswith("__quick_helper"))


def kernels(modules=KERNEL_MODULES):
    """The cached kernels defined in ``modules``: one dispatcher each, in definition order.
    Helpers inlined at Numba IR level (``inline="always"``) are left out: they are compiled
    into their callers and have no cache entry of their own."""
    found = {}
    for name in modules:
        mod = importlib.import_module(name)
        for obj in vars(mod).values():
            if (_is_kernel(obj) and obj.py_func.__module__ == name
                    and obj.targetoptions.get("inline") != "always"):
                found.setdefault(id(obj), obj)
    return list(found.values())


def _name(disp):
    return f"{disp.py_func.__module__}.{disp.py_func.__qualname__}"


def _cached(disp):
    """Whether ``disp`` has at least one compiled specialisation in the on-disk cache that is
    valid for its current source (Numba drops an index whose source file has changed)."""
    try:
        return bool(disp._cache._cache_file._load_index())
    except Exception:   # an unreadable index is a cold one: Numba will compile
        return False


def cache_state(modules=KERNEL_MODULES, only=None):
    """``(cached, total)``: how many of the kernels of ``modules`` (of these, those named in
    ``only``) are in the cache."""
    ks = [d for d in kernels(modules) if only is None or _name(d) in only]
    return sum(map(_cached, ks)), len(ks)


def compile_listener(callback, on_start=None):
    """A context manager: ``callback(dispatcher)`` after each kernel compiled (not loaded from
    the cache) while it is active, in any thread of this process; ``on_start(dispatcher)``
    when one starts compiling."""
    from numba.core import event

    class _Listener(event.Listener):
        def on_start(self, ev):
            disp = ev.data.get("dispatcher")
            if on_start is not None and disp is not None and _is_kernel(disp):
                on_start(disp)

        def on_end(self, ev):
            disp = ev.data.get("dispatcher")
            if disp is not None and _is_kernel(disp):
                callback(disp)

    return event.install_listener("numba:compile", _Listener())


class CompileProgress:
    """Counts the kernels compiled while active and reports them on ``stream``.

    ``n`` is the number of kernels of ``modules`` (of these, those named in ``only`` and not
    in ``skip``) not in the cache when it starts; a kernel compiled that was not counted adds one. With nothing
    to compile it prints nothing. On a terminal the line is redrawn as kernels finish
    ("compiling kernels, first run only: k of n"); elsewhere (logs, CI) it is printed when the
    first kernel is compiled and once more at the end, with the time it took. Kernels compiled
    in worker processes are added with :meth:`add`.
    """

    def __init__(self, modules=KERNEL_MODULES, *, only=None, skip=(), stream=None,
                 quiet=False):
        self.stream = sys.stderr if stream is None else stream
        self.quiet = quiet
        self.pending = {name for name, d in ((_name(d), d) for d in kernels(modules))
                        if (only is None or name in only) and name not in skip
                        and not _cached(d)}
        self.n = len(self.pending)
        self.done = set()
        self.t0 = None
        self.seconds = 0.0
        self._lock = threading.Lock()
        self._tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._cm = None
        self._said = False

    @property
    def k(self):
        return len(self.done)

    @property
    def total(self):
        return len(self.pending | self.done)

    def expect(self, names):
        """Count ``names`` (``module.qualname``) as the kernels to compile instead of those not
        in the cache at the start (a quick-tier render compiles the quick twins instead)."""
        with self._lock:
            self.pending = set(names)

    def add(self, name):
        """Count the kernel named ``module.qualname`` as compiled (from any process)."""
        with self._lock:
            if name in self.done:
                return
            self._header()
            self.done.add(name)
            if self._tty and not self.quiet:
                self.stream.write(f"\r{COMPILING}: {self.k} of {self.total}")
                self.stream.flush()

    def starting(self, name=None):
        """A kernel starts compiling: say so at once (the first compile can take a minute)."""
        with self._lock:
            self._header()

    def _header(self):
        if self._said or self.quiet:
            return
        self._said = True
        if self._tty:
            self.stream.write(f"\r{COMPILING}: {self.k} of {self.total}")
        else:
            self.stream.write(f"{COMPILING}: {self.total} kernels not in the cache "
                              f"({os.environ.get('NUMBA_CACHE_DIR') or 'Numba default cache'})\n")
        self.stream.flush()

    def __enter__(self):
        self.t0 = time.perf_counter()
        self._cm = compile_listener(lambda d: self.add(_name(d)), lambda d: self.starting())
        self._cm.__enter__()
        return self

    def __exit__(self, *exc):
        self._cm.__exit__(*exc)
        self.seconds = time.perf_counter() - self.t0
        if self.done and not self.quiet:
            n = self.total
            self.stream.write(("\r" if self._tty else "")
                              + f"{COMPILING}: {self.k} of {n}, {self.seconds:.1f} s "
                              "(later runs load them from the cache)\n")
            self.stream.flush()
        return False


# ---------------------------------------------------------------------------------------------
# what compiles the kernels: small workloads with the types of the real ones

def _box():
    import numpy as np
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)],
                 np.float64)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.int64)
    return v, f


def warm_core(normals=("flat", "smooth"), *, clip=False, stream=False, reusable=False,
              multisample=False):
    """Compile the kernels of ``refraster.render`` (and the colour read): a 16×12 frame of a
    cube per normals mode. ``clip=True`` also draws the cube cut by the near plane (the
    clipping kernels), ``stream=True`` through a fragment stage (``draw``, ``resolve``): what
    the gallery's techniques share. ``reusable=True`` also renders twice into a
    :meth:`Framebuffer.reusable <refraster.framebuffer.Framebuffer.reusable>` (its span clear,
    ``refraster warmup``'s). ``multisample=True`` also runs ``render_samples`` (its sample
    positions, the primitive stage's half-pixel pad, ``finalize``'s sample image) with its tile
    pass replaced by a no-op for the call (the tile pass compiles where a multisampled frame is
    first drawn; the replacement is process-wide, as :func:`warm_only`'s): what the gallery's
    and the goldens' 4× pictures add to the pipeline's kernels."""
    import numpy as np

    import refraster
    from refraster.camera import look_at, perspective
    mesh = refraster.as_mesh(_box())
    view = look_at((0.3, 0.4, 2.0), (0.0, 0.0, 0.0))
    for near in (0.5, 1.9) if clip else (0.5,):   # 1.9 cuts the cube: clipped pieces
        proj = perspective(40.0, 4 / 3, near, 10.0)
        for mode in normals:
            state = refraster.RasterState(normals=mode)
            fb = refraster.render(mesh, view=view, proj=proj, width=16, height=12, raster=state)
            np.asarray(fb.color)
            if stream:
                fb = refraster.render(mesh, view=view, proj=proj, width=16, height=12,
                                      raster=state,
                                      fragment_stage=lambda f: f.world_position()[:, 0] <= 0.0)
                np.asarray(fb.color)
    if multisample:
        proj = perspective(40.0, 4 / 3, 0.5, 10.0)
        with _stubbed(("refraster.raster.multisample._msaa_pass",)):
            for mode in normals:
                state = refraster.RasterState(normals=mode, samples=4)
                fb = refraster.render_samples(mesh, view=view, proj=proj, width=16, height=12,
                                              raster=state)
                np.asarray(fb.color)
    if reusable:
        from refraster.framebuffer import Framebuffer
        proj = perspective(40.0, 4 / 3, 0.5, 10.0)
        fb = Framebuffer.reusable(16, 12)
        for _ in range(2):
            refraster.render(mesh, view=view, proj=proj, width=16, height=12, out=fb)


#: The kernel the second process of :func:`warm_core_split` compiles: the fused tile kernel,
#: over half of a first ``render``'s compile time (``_fused_pass`` 57.7 of 109.0 s of compiling
#: at load 5, 2026-12-02; docs/performance.md, "The first render: inlining traded or not, and
#: two processes").
SPLIT_KERNEL = "refraster.raster.rasterizer._fused_pass"


def _nothing(*args):
    """Stands in for a kernel in a half of :func:`warm_core_split`: the other process
    compiles that one; here only the types of the arrays around it matter."""
    return None


def _no_fragment_wins(*args):
    """Stands in for the fused tile pass (``refraster.raster.rasterizer._fused_pass``) in a
    half of :func:`warm_core_split`: no fragment wins anywhere. The pass itself writes the
    face image's −1 where nothing won (its ``fill_face``; the face image comes to it
    unfilled), so this writes it too: the G-buffer kernels after it read that image."""
    *_, fill_face, _depth, face, _front, _bary = args
    if fill_face:
        face.fill(-1)


#: Stand-ins other than :func:`_nothing`, by the kernel's module attribute.
_STAND_INS = {"refraster.raster.rasterizer._fused_pass": _no_fragment_wins}


class _stubbed:
    """Replace module attributes (kernels) by :func:`_nothing` (or their entry of
    :data:`_STAND_INS`) for the body of a ``with``; restored after it, whatever happens."""

    def __init__(self, names):
        self.names = names
        self.saved = []

    def __enter__(self):
        for name in self.names:
            module, attr = name.rsplit(".", 1)
            mod = importlib.import_module(module)
            self.saved.append((mod, attr, getattr(mod, attr)))
            setattr(mod, attr, _STAND_INS.get(name, _nothing))
        return self

    def __exit__(self, *exc):
        for mod, attr, value in reversed(self.saved):
            setattr(mod, attr, value)
        return False


#: Where ``render``'s path calls each of :data:`RENDER_KERNELS` (the module attribute a half of
#: :func:`warm_core_split` replaces so as not to compile it).
_CALL_SITES = {
    "refraster.raster.primitive._transform32": ("refraster.raster.primitive._transform32",),
    "refraster.raster.primitive._vertex_pass": ("refraster.raster.primitive._vertex_pass",),
    "refraster.raster.primitive._classify": ("refraster.raster.primitive._classify",),
    "refraster.raster.rasterizer._bin_pass": ("refraster.raster.rasterizer._bin_pass",),
    "refraster.raster.rasterizer._fused_pass": ("refraster.raster.rasterizer._fused_pass",),
    "refraster.raster.gbuffer.finalize": ("refraster.framebuffer.finalize",),
    "refraster.raster.gbuffer.shade": ("refraster.framebuffer.shade",),
}


def warm_only(kernels, normals="flat"):
    """Compile only ``kernels`` (names of :data:`RENDER_KERNELS`) of ``render``'s path: the
    16×12 frame of :func:`warm_core` with every other kernel of the path replaced by a no-op
    for the call, so that these get the argument types a render gives them (the arrays around
    a replaced kernel are allocated by the same wrappers; they keep their fill values). The
    replacement is process-wide for the call: for the command's process or the second
    process, not while other threads of the process render."""
    import numpy as np

    import refraster
    from refraster.camera import look_at, perspective
    others = [site for name, sites in _CALL_SITES.items() if name not in kernels
              for site in sites]
    mesh = refraster.as_mesh(_box())
    view = look_at((0.3, 0.4, 2.0), (0.0, 0.0, 0.0))
    proj = perspective(40.0, 4 / 3, 0.5, 10.0)
    with _stubbed(others):
        fb = refraster.render(mesh, view=view, proj=proj, width=16, height=12,
                              raster=refraster.RasterState(normals=normals))
        np.asarray(fb.color)


def _split_worth_it():
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    return cpus >= 2


def warm_core_split(normals=("flat",), *, progress=None):
    """:func:`warm_core` for a first ``render`` on two cores: when :data:`SPLIT_KERNEL` (the
    fused tile kernel, over half the compile time) is not in the cache, a second process
    (``python -m refraster.warmup``) compiles it into the cache while this one compiles the
    other six kernels of the path (:func:`warm_only`); this one then waits for it and runs
    :func:`warm_core`, which loads all seven. Same kernels, same specialisations, same cache
    as :func:`warm_core` (``tests/test_warmup.py``); if the second process fails, this one
    compiles the kernel itself. ``progress``: a :class:`CompileProgress` to add the kernel
    the second process compiled to."""
    import subprocess

    fused = [d for d in kernels(CORE_MODULES) if _name(d) == SPLIT_KERNEL]
    proc = None
    if fused and not _cached(fused[0]) and _split_worth_it():
        try:
            proc = subprocess.Popen([sys.executable, "-m", "refraster.warmup", SPLIT_KERNEL],
                                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL)
        except OSError:
            proc = None
    if proc is not None:
        if progress is not None:
            progress.starting()
        try:
            for mode in normals:
                warm_only([k for k in RENDER_KERNELS if k != SPLIT_KERNEL], mode)
        finally:
            status = proc.wait()
        if status == 0 and progress is not None and _cached(fused[0]):
            progress.add(SPLIT_KERNEL)
    warm_core(tuple(normals))


def warm_clipsurface_side():
    """Compile :data:`CLIPSURFACE_SIDE_KERNELS` (over half of the clip surfaces' compile
    time, 2026-12-01) on tiny inputs, through the wrappers the clip-surface renderer calls,
    so that each gets the one specialisation a render uses (``tests/test_warmup.py`` checks that the gallery's
    section adds none). Needs no pipeline kernel: on a first ``refraster gallery`` a worker
    runs it while the parent compiles the pipeline's kernels, and the clip-surface section
    then loads these from the cache instead of compiling them on its own core."""
    from types import SimpleNamespace

    import numpy as np

    from refraster.clipsurface import ClipSurface, capping, clip_mask, offsetmaps, textures
    rng = np.random.default_rng(0)
    surface = ClipSurface([0.05, 0.0, 0.0], [0.0, 2.0, 0.4], [0.0, -0.4, 2.0], (1.0, 1.0, 0.4),
                          offsetmaps.perlin_noise(8, seed=5))
    surface.occlusion_map()
    offsetmaps.sample(surface.offset_map, rng.random((4, 2)))
    v, f = _box()
    h, w = 2, 3
    gbuffer = SimpleNamespace(
        object_id=np.ones((h, w), np.int32), prim_id=np.zeros((h, w), np.int32),
        barycentric=np.full((h, w, 3), 1 / 3, np.float32), color=np.zeros((h, w, 3), np.float32),
        normal=np.zeros((h, w, 3), np.float32))
    view = np.eye(4)
    view[2, 3] = -3.0
    # every pixel: draw call 1 (the cap of surface 0 on solid 0), its face 0 (draw call 1's
    # faces start at face 0 here: face_offsets [0, 0])
    capping.shade_cap_pixels(np.arange(h * w, dtype=np.int64), gbuffer, 1, 1, f,
                             np.zeros(2, np.int64), v, [surface], view=view,
                             style="diffuse", color=(0.5, 0.5, 0.5), hatch_spacing=0.1,
                             frequency=1.0)
    points = rng.random((4, 3)) - 0.5
    clip_mask(points, [surface])
    capping.light_caps(points, np.zeros(4, np.int64), [surface], view=view)
    textures.sample_texture(rng.random((4, 4, 3)), rng.random((4, 2)))
    textures.sample_volume(rng.random((2, 3, 4, 3)), rng.random((4, 3)))
    capping._same_bits(v, v.copy())


#: The pipeline kernels :func:`warm_fused_clip` replaces by no-ops (the module attributes
#: ``prepare`` and ``bin_primitives`` call): the arrays around them are allocated by the same
#: wrappers, zero-filled, so every face stays ``SKIP`` and the tile lists empty.
_FUSED_CLIP_STUBS = ("refraster.raster.primitive._transform32",
                     "refraster.raster.primitive._transform64",
                     "refraster.raster.primitive._vertex_pass",
                     "refraster.raster.primitive._classify",
                     "refraster.raster.primitive._clip_pass",
                     "refraster.raster.rasterizer._bin_pass")

#: The clip surfaces' fused tile pass, compiled by :func:`warm_fused_clip`.
FUSED_CLIP_KERNEL = "refraster.clipsurface.fused._fused_clip_pass"


def warm_fused_clip():
    """Compile :data:`FUSED_CLIP_KERNEL` (the clip surfaces' fused tile pass, the largest single
    compile of a cold golden generation) without the pipeline's kernels: ``render_clipped``'s
    own call (``refraster.clipsurface.fused._fused_clip``) on a 16×12 frame whose primitive
    stage and binning are replaced by no-ops (:data:`_FUSED_CLIP_STUBS`; every face stays
    ``SKIP``, so the pass draws nothing), with the argument types a render passes: a solid and
    a cap draw call (the vertices concatenated, writable), no sprite (the sprites' arrays are
    typed as the real ones). It is the one specialisation the golden clip-surface scenes use
    (a single draw call of read-only vertices would pass them read-only: another one).
    ``tests/test_warmup.py`` checks that a real clip-surface golden scene then compiles no new
    specialisation. The replacement is process-wide for the call: for a worker's warm task,
    not while other threads of the process render."""
    import numpy as np

    import refraster
    from refraster.camera import look_at, perspective
    from refraster.clipsurface import ClipSurface, offsetmaps
    from refraster.clipsurface.fused import _fused_clip
    from refraster.clipsurface.render import _concat_vertices, _surfaces_in_space
    from refraster.raster import prepare
    from refraster.raster.fragments import vertices_in
    surface = ClipSurface([0.05, 0.0, 0.0], [0.0, 2.0, 0.4], [0.0, -0.4, 2.0], (1.0, 1.0, 0.4),
                          offsetmaps.perlin_noise(8, seed=5))
    solid = refraster.as_mesh(_box())
    view = look_at((0.3, 0.4, 2.0), (0.0, 0.0, 0.0))
    proj = perspective(40.0, 4 / 3, 0.5, 10.0)
    with _stubbed(_FUSED_CLIP_STUBS):
        draws = [solid, solid]   # the solid and its cap: render_clipped's draw list with caps
        prep = prepare(draws, view=view, proj=proj, width=16, height=12,
                       model=[np.eye(4)] * len(draws))
        tv = _concat_vertices(vertices_in(prep.meshes, prep.models, view, "world"))
        _fused_clip(prep, tv, tv, 1, _surfaces_in_space([surface], "world", view), None, [None])


def warm_full_tier(stream=None):
    """The second process of a quick-tier first render (:mod:`refraster._tiers`): compile the
    quick twins of :data:`refraster._tiers.SPLIT_KERNELS` (the parent compiles the others
    meanwhile), naming each group on ``stream`` (default stdout; the parent waits for a name
    before it calls that kernel), then, at a lower priority, the full tier of the render
    kernels, all into the cache. One such process per cache directory at a time (a lock file
    beside the fused kernel's cache files): a second one only says ``busy`` and ends (the
    parent then compiles what it needs)."""
    from . import _tiers
    out = sys.stdout if stream is None else stream
    lock = _tier_lock()
    if lock is False:
        out.write("busy\n")
        out.flush()
        return
    try:
        if _tiers.split_wanted():
            _tiers.force(_tiers.QUICK)
            for group in _tiers.SPLIT_KERNELS:
                warm_only(list(group))
                out.write(" ".join(group) + "\n")
                out.flush()
        out.write("done\n")
        out.flush()
        try:
            os.nice(5)
        except (AttributeError, OSError):
            pass
        _tiers.force(_tiers.FULL)
        warm_core(("flat",))
    finally:
        if lock is not None:
            lock.close()


def _tier_lock():
    """An exclusive lock on ``refraster-full-tier.lock`` in the fused kernel's cache
    directory: the open file (closing it unlocks), ``False`` when another process holds it,
    ``None`` when locks are not available here (then there is no lock)."""
    try:
        import fcntl
        from . import _tiers
        path = os.path.join(_tiers._dispatcher(SPLIT_KERNEL)._cache._cache_path,
                            "refraster-full-tier.lock")
        fh = open(path, "a")
    except (ImportError, AttributeError, OSError):
        return None
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        return False
    return fh


if __name__ == "__main__":
    if sys.argv[1:] == ["--full-tier"]:   # the second process of a quick-tier first render
        warm_full_tier()
    else:   # the second process of warm_core_split: compile the named kernels
        warm_only(sys.argv[1:])
