"""What the driver and the technique modules of refraster.gl share: the shader files, the
errors, the programs compiled once per backend and the full-screen pass.

The driver (:mod:`refraster.gl.driver`) imports the technique modules (``clipsurface``,
``edges``, ``cutaway``, ``halos``) and this module; the technique modules import this module
and :mod:`refraster.gl.package`, never the driver (``tests/test_architecture.py``). The
``gl`` argument of the functions here is the driver's ``Backend`` (its context ``ctx``, its
moderngl module ``mgl``, its planted ``faults`` and its program cache).
"""

from __future__ import annotations

from pathlib import Path

from . import FAULTS

__all__ = ["SHADER_DIR", "GLUnavailable", "Unsupported", "shader_source", "programs",
           "fullscreen"]

SHADER_DIR = Path(__file__).with_name("shaders")


class GLUnavailable(RuntimeError):
    """No OpenGL 3.3 core context could be created (moderngl or EGL missing)."""


def gl_function(name, restype, *argtypes):
    """A GL entry point moderngl does not wrap, through ``eglGetProcAddress`` (the context is
    EGL's); :class:`GLUnavailable` with one line when EGL or the function is missing."""
    import ctypes
    import ctypes.util
    path = ctypes.util.find_library("EGL") or "libEGL.so.1"
    try:
        egl = ctypes.CDLL(path)
    except OSError as exc:
        raise GLUnavailable(f"cannot load {path}: {exc}") from None
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    addr = egl.eglGetProcAddress(name.encode())
    if not addr:
        raise GLUnavailable(f"eglGetProcAddress({name}) returned NULL")
    return ctypes.CFUNCTYPE(restype, *argtypes)(addr)


class Unsupported(Exception):
    """The scene's technique (or a setting of it) is not implemented by this backend."""


def shader_source(name, defines=()):
    """The text of ``shaders/<name>`` with ``#define`` lines inserted after ``#version`` and
    each ``#include "file"`` line replaced by ``shaders/file``'s text (GLSL has no include;
    the line may sit inside an ``#ifdef``)."""
    text = (SHADER_DIR / name).read_text(encoding="utf-8")
    text = "".join((SHADER_DIR / line.split('"')[1]).read_text(encoding="utf-8")
                   if line.startswith("#include ") else line
                   for line in text.splitlines(keepends=True))
    if not defines:
        return text
    lines = text.splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if line.startswith("#version")) + 1
    return "".join(lines[:at] + [f"#define {d}\n" for d in defines] + lines[at:])


def programs(gl, shaders):
    """A technique module's programs: ``shaders`` maps a name to the shader files
    ``(vertex, geometry or None, fragment)`` under ``shaders/``, optionally followed by a
    tuple of ``#define``s of that program's variant (e.g. ``("MSAA",)``); they are compiled
    once per backend (its context, with its planted faults) and cached on it, keyed by
    ``shaders``. → ``{name: program}``."""
    key = tuple(shaders.items())
    if key not in gl._programs:
        faults = [FAULTS[f][0] for f in gl.faults]
        built = {}
        for name, (vert, geom, frag, *variant) in shaders.items():
            defines = faults + list(variant[0] if variant else ())
            built[name] = gl.ctx.program(
                vertex_shader=shader_source(vert, defines),
                geometry_shader=None if geom is None else shader_source(geom, defines),
                fragment_shader=shader_source(frag, defines))
        gl._programs[key] = built
    return gl._programs[key]


def fullscreen(gl, prog):
    """One full-screen triangle drawn with ``prog`` (its vertex shader ``fullscreen.vert``
    makes the positions from ``gl_VertexID``)."""
    vao = gl.ctx.vertex_array(prog, [])
    try:
        vao.render(gl.mgl.TRIANGLES, vertices=3)
    finally:
        vao.release()
