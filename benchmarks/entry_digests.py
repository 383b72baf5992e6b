"""SHA-256 digests of what every technique's entry point returns, each option away from its
default at least once.

    python -m benchmarks.entry_digests --check FILE         # compare (exit 1, naming each case)
    python -m benchmarks.entry_digests --add FILE NAME ...  # record new cases into FILE
    python -m benchmarks.entry_digests --write FILE         # record every case (a new FILE)
    python -m benchmarks.entry_digests --list [-v]          # the cases (-v: run each, timed)
    ... -k SUBSTRING                                        # --check, --list: only the cases
                                                            # whose name contains it

FILE is ``benchmarks/entry_digests.json``, the baseline.

The guard of the public signatures: a change of the API (issue 38: the raster state and the
techniques' option groups as values) translates the cases where they stand and must leave
every digest as it was. ``--check`` names every case whose outputs differ (and which
outputs), every case that raised, every case the file has and the module not (MISSING) and
the reverse (NEW). Run it under ``NUMBA_NUM_THREADS`` (and ``REFRASTER_THREADS``) ``=1`` and
``=2``: the outputs are the same for any thread count.

The baseline ``benchmarks/entry_digests.json`` was recorded at a469114, with the keywords of
that API (``render(normals=array, cull=..., depth_func=...)``, ``render_clipped(cap_style=...)``,
``render_cutaway(angle=..., ghost_distance=...)``, ``render_halos(rotation=..., opacity=...)``,
``npr.render_mirrored(reflectance=...)``); the cases now pass ``raster=RasterState(...)``,
``caps=Caps(...)``, ``Cutaway``/``CutSurfaces``/``GhostLines``, ``View4D``/``Halos``/
``HaloStyle`` and ``MirrorStyle``, a given normal array as a ``(vertices, faces, normals)``
triple or ``Mesh`` rendered with ``normals="smooth"``, with the same digests. **The file is
rewritten (``--write``) only when an issue says that outputs change**, and the commit names
the cases that changed and why; a refactor never rewrites it, and a new case is recorded with
``--add FILE NAME ...``, which refuses a name the file already has. Recorded with ``--add``
(the old API had no such option): ``render_front_face_cw``,
``render_front_face_cw_cull_back``, ``render_depth_write_false``. Issue 46 made the paper's jump
flooding (``"jfa"``) the cutaways' default flooding variant in place of ``"jfa+1"``: the eight
cases it changed (``cut_view2``, ``cut_perspective_compensation_false``, ``cut_edge_stand_in``,
``cut_edge_compression_none`` / ``_zero`` / ``_value``, ``cut_floor_margin``,
``cut_floor_view2``) were re-recorded, and each has a twin with ``Cutaway(variant="jfa+1")``
(``cut_variant_jfa1``, ``*_jfa1``) that keeps its former digest; ``cut_view2`` and
``cut_variant_jfa`` are now equal by design. Issue 46 also made the halos' default prism split the paper's repair
(``Halos(split="paper")``): the 34 ``halo_*`` cases of ``render_halos``/``render_halos_pair``
were re-recorded (with the new halo defaults of the same issue); the new
``halo_split_global_index*`` cases keep ``split="global_index"``.

Each case is one small function ``case_NAME()`` whose calls are written out, so an API change
translates each case where it stands; it returns its outputs as ``{name: value}``, result
records flattened by :func:`_of` into every field (``color`` included, ``meshes`` left out).
A digest is SHA-256 of dtype, shape and bytes for arrays and numbers (a number as a 0-d
array, so ``3`` and ``np.int64(3)`` agree) and of the JSON text for strings and ``None``.

Covered: ``refraster.render``, ``draw``, ``resolve``, ``rasterize``,
``Framebuffer.from_fragments``; ``refraster.ldi`` (``peel``, ``peel_fragments``, the volumetric
depth sprite, ``parity_at``); ``refraster.clipsurface.render_clipped``;
``refraster.cutaway.render_cutaway``; ``refraster.halos4d.render_halos`` and
``render_halos_pair``; ``refraster.edges.npr.render_mirrored`` and the NPR styles;
``refraster.edges`` (``edge_gbuffer``, ``edge_map``, ``classify_edges``);
``refraster.render_samples`` (``samples_*``: 1×, 2×/4×/8× with each interpolation, 16×, the
``gl_llvmpipe`` and user patterns, ties with the top-left rule, ``greater``/``lequal``, clipped
pieces, slivers that snapping flips; every per-sample buffer and the positions; recorded with
``--add`` before the MSAA speed work of issue 43). Each option case has
a neighbour it differs from (``*_defaults`` or a named base: ``render_twice``,
``render_ties``, ``cut_view2``, ``cut_edge_stand_in``, ``clip_vds_resolution_64``,
``mirror_model`` …), with scenes chosen so that the option changes bytes (ties at equal
depth, edges through pixel centres, seeds near the border, a non-rigid view for
``space="eye"``). Equal by design: ``fill_rule="bottom-left"`` and the default
(``"llvmpipe"``); ``RasterState(normals="flat")`` and the default state;
``Cutaway(edge_compression=None)`` and ``0``; the two halo engines; a duck-typed ``vds`` and
a sprite; ``out=`` and a fresh framebuffer.

Frames are at most 128×96 (halos 48×40, 12 slices); a warm run takes well under a minute on
one core.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import hashlib
import json
import os
import sys
import tempfile
import time
import warnings

import numpy as np

from refraster.raster.state import RasterState

# ============================================================================== digests


def _digest(value):
    if isinstance(value, (bool, int, float, np.generic)):
        value = np.asarray(value)      # 3 and np.int64(3) alike; np.float32 stays float32
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            raise TypeError("object arrays have no stable bytes")
        a = np.ascontiguousarray(value)
        data = f"{a.dtype.str}{a.shape}".encode() + a.tobytes()
    else:
        data = ("py:" + json.dumps(value, sort_keys=True, default=repr)).encode()
    return hashlib.sha256(data).hexdigest()


def _of(obj, prefix="", out=None):
    """Flatten a result into ``{name: array or scalar}``: dataclass fields (``color`` through
    its property, ``meshes`` left out), dicts, lists and tuples, objects' attributes."""
    out = {} if out is None else out
    if isinstance(obj, np.ndarray) or obj is None or isinstance(
            obj, (bool, int, float, str, np.generic)):
        out[prefix or "value"] = obj
    elif isinstance(obj, dict):
        for k in sorted(obj):
            _of(obj[k], f"{prefix}.{k}" if prefix else str(k), out)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _of(v, f"{prefix}[{i}]", out)
    elif dataclasses.is_dataclass(obj):
        for f in dataclasses.fields(obj):
            if f.name != "meshes":
                _of(getattr(obj, f.name), f"{prefix}.{f.name}" if prefix else f.name, out)
    elif hasattr(obj, "__dict__"):
        for k in sorted(vars(obj)):
            if not k.startswith("_"):
                _of(getattr(obj, k), f"{prefix}.{k}" if prefix else k, out)
    else:
        raise TypeError(f"{prefix}: cannot digest {type(obj).__name__}")
    return out


def _frags(fr):
    """A fragment stream's arrays."""
    return dict(pixel=fr.pixel, depth=fr.depth, prim_id=fr.prim_id, object_id=fr.object_id,
                bary=fr.bary, front_facing=fr.front_facing, width=fr.width, height=fr.height)


def _sprite(vds):
    """Every array a volumetric depth sprite saves (all its axes), its parity test (both
    rules) on a fixed point grid, and its first-axis attributes."""
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "s.npz")
        vds.save(path)
        with np.load(path, allow_pickle=False) as z:
            out = {f"saved.{k}": z[k] for k in z.files}
    pts = _grid_points()
    out["contains_parity"] = vds.contains(pts)
    out["contains_nonzero"] = vds.contains(pts, rule="nonzero")
    out.update(G=vds.G, scale=vds.scale, axes=vds.axes, M=vds.M, B=vds.B, d=vds.d, w=vds.w,
               h=vds.h)
    return out


@functools.cache
def _grid_points():
    g = np.linspace(-0.7, 0.7, 15)
    return np.stack(np.meshgrid(g, g + 0.013, g - 0.021, indexing="ij"), -1).reshape(-1, 3)


# ============================================================================== scenes


def _arrays(m):
    return (np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))


@functools.cache
def _torus():
    from refraster import scenes
    return _arrays(scenes.torus(major_segments=32, minor_segments=12))


@functools.cache
def _ico():
    from refraster import scenes
    return _arrays(scenes.icosphere(2))


@functools.cache
def _cube():
    from refraster import scenes
    return _arrays(scenes.cube())


@functools.cache
def _box():
    import trimesh
    return _arrays(trimesh.creation.box((1.0, 1.0, 1.0)))


@functools.cache
def _open_torus():
    """A quarter of the torus's faces removed: its inside (back faces) shows."""
    v, f = _torus()
    return v, f[len(f) // 4:]


@functools.cache
def _ties():
    """Edges through pixel centres under :func:`_tie_cam` (corners on half-integers): a square
    split along its diagonal, two rectangles sharing a vertical edge, two sharing a horizontal
    one. The fill rules give each centre on a shared edge to different triangles."""
    quads = [((-20.5, -10.5), (-4.5, 5.5)), ((0.5, -15.5), (8.5, -0.5)),
             ((8.5, -15.5), (20.5, -0.5)), ((0.5, 2.5), (20.5, 10.5)),
             ((0.5, 10.5), (20.5, 18.5))]
    v, f = [], []
    for k, ((x0, y0), (x1, y1)) in enumerate(quads):
        v += [(x0, y0, -1.0), (x1, y0, -1.0), (x1, y1, -1.0), (x0, y1, -1.0)]
        f += [(4 * k, 4 * k + 1, 4 * k + 2), (4 * k, 4 * k + 2, 4 * k + 3)]
    return np.array(v), np.array(f, np.int64)


def _tie_cam():
    """One world unit per pixel: world x = window x − 32, pixel centres at half-integers."""
    import refraster as rf
    return dict(view=np.eye(4), proj=rf.orthographic(-32, 32, -24, 24, 0.1, 10.0), width=64,
                height=48)


def _cam(w=96, h=72, eye=(1.6, 1.2, 2.4)):
    import refraster as rf
    return dict(view=rf.look_at(list(eye), [0, 0, 0]), proj=rf.perspective(45, w / h, 0.5, 10),
                width=w, height=h)


def _shift(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def _turn(angle, axis):
    import trimesh
    return trimesh.transformations.rotation_matrix(angle, axis)


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# ============================================================================== refraster.render
# defaults: raster=None (RasterState(): depth_func="less", depth_write=True, clear_depth=1.0,
# cull="none", front_face="ccw", subpixel_bits=8, fill_rule="llvmpipe", precision="float32",
# normals="flat"), model=None, fragment_stage=None, background=(1, 1, 1), out=None; a mesh's
# own normals: (vertices, faces, normals) or Mesh(v, f, n), used with normals="smooth"


def case_render_defaults():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam()))


def case_render_open_torus():
    """The default culling (none) of the open torus: what the cull cases differ from."""
    import refraster as rf
    return _of(rf.render(_open_torus(), **_cam()))


def _twice():
    """The open torus drawn twice (draw calls 0 and 1 at equal depths; pixels with one layer
    and with several): the depth functions' ties decide which draw call shows."""
    return [_open_torus(), _open_torus()]


def case_render_normals_flat():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), raster=rf.RasterState(normals="flat")))


def case_render_normals_smooth():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), raster=rf.RasterState(normals="smooth")))


def case_render_normals_array():
    """Given vertex normals (once ``normals=array``): a ``(vertices, faces, normals)`` triple
    rendered with ``normals="smooth"``."""
    import refraster as rf
    return _of(rf.render((*_torus(), _unit(_torus()[0])), **_cam(),
                         raster=rf.RasterState(normals="smooth")))


def case_render_normals_list():
    """Given vertex normals per draw call (once ``normals=[array, ...]``): one triple each."""
    import refraster as rf
    return _of(rf.render([(*_torus(), _unit(_torus()[0])), (*_ico(), _unit(_ico()[0]))], **_cam(),
                         model=[np.eye(4), _shift(0.3, 0.2, -0.4)],
                         raster=rf.RasterState(normals="smooth")))


def case_render_cull_back():
    import refraster as rf
    return _of(rf.render(_open_torus(), **_cam(), raster=rf.RasterState(cull="back")))


def case_render_cull_front():
    import refraster as rf
    return _of(rf.render(_open_torus(), **_cam(), raster=rf.RasterState(cull="front")))


def case_render_twice():
    """The default depth function ("less") on the open torus drawn twice."""
    import refraster as rf
    return _of(rf.render(_twice(), **_cam()))


def case_render_depth_func_lequal():
    import refraster as rf
    return _of(rf.render(_twice(), **_cam(), raster=rf.RasterState(depth_func="lequal")))


def case_render_depth_func_greater():
    import refraster as rf
    return _of(rf.render(_twice(), **_cam(),
                         raster=rf.RasterState(depth_func="greater", clear_depth=0.0)))


def case_render_depth_func_gequal():
    import refraster as rf
    return _of(rf.render(_twice(), **_cam(),
                         raster=rf.RasterState(depth_func="gequal", clear_depth=0.0)))


def case_render_depth_func_notequal():
    import refraster as rf
    return _of(rf.render(_twice(), **_cam(), raster=rf.RasterState(depth_func="notequal")))


def case_render_depth_func_always():
    import refraster as rf
    return _of(rf.render(_twice(), **_cam(), raster=rf.RasterState(depth_func="always")))


def case_render_depth_func_never():
    import refraster as rf
    return _of(rf.render(_twice(), **_cam(), raster=rf.RasterState(depth_func="never")))


def case_render_depth_func_equal():
    """A quad facing an orthographic camera has one depth; clear to it, and "equal" passes."""
    import refraster as rf
    quad = (np.array([[-0.8, -0.6, -0.5], [0.8, -0.6, -0.5], [0.8, 0.6, -0.5],
                      [-0.8, 0.6, -0.5]]), np.array([[0, 1, 2], [0, 2, 3]]))
    cam = dict(view=np.eye(4), proj=rf.orthographic(-1, 1, -0.75, 0.75, 0.1, 3.0), width=64,
               height=48)
    plain = rf.render(quad, **cam)
    z = float(plain.depth[24, 32])
    return {"plain_depth": plain.depth,
            **_of(rf.render(quad, **cam,
                            raster=rf.RasterState(depth_func="equal", clear_depth=z)))}


def case_render_clear_depth():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), raster=rf.RasterState(clear_depth=0.62)))


def case_render_model_one():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), model=_turn(0.7, [1, 0, 0]) @ _shift(0, 0.1, 0)))


def case_render_model_list():
    import refraster as rf
    return _of(rf.render([_cube(), _ico()], **_cam(), model=[np.eye(4), _shift(0.4, 0.1, -0.3)],
                         raster=rf.RasterState(normals="smooth")))


def case_render_precision_float64():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), raster=rf.RasterState(precision="float64")))


def case_render_subpixel_bits_4():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), raster=rf.RasterState(subpixel_bits=4)))


def case_render_ties():
    """The default fill rule ("llvmpipe") on edges through pixel centres."""
    import refraster as rf
    return _of(rf.render(_ties(), **_tie_cam()))


def case_render_fill_rule_top_left():
    import refraster as rf
    return _of(rf.render(_ties(), **_tie_cam(), raster=rf.RasterState(fill_rule="top-left")))


def case_render_fill_rule_bottom_left():
    import refraster as rf
    return _of(rf.render(_ties(), **_tie_cam(), raster=rf.RasterState(fill_rule="bottom-left")))


def case_render_fragment_stage():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), raster=rf.RasterState(normals="smooth"),
                         fragment_stage=lambda fr: fr.depth < 0.9))


def case_render_fragment_stage_options():
    """The stream path with the other options: cull, depth function, clear, precision, bits,
    fill rule, models, background."""
    import refraster as rf
    return _of(rf.render([_torus(), _ico()], **_cam(),
                         raster=rf.RasterState(cull="back", depth_func="lequal",
                                               clear_depth=0.95, precision="float64",
                                               subpixel_bits=4, fill_rule="top-left"),
                         model=[np.eye(4), _shift(0.3, 0, 0.2)],
                         background=(0.1, 0.2, 0.3),
                         fragment_stage=lambda fr: fr.prim_id % 3 != 0))


def case_render_background():
    import refraster as rf
    return _of(rf.render(_torus(), **_cam(), background=(0.2, 0.4, 0.6)))


def case_render_out():
    import refraster as rf
    out = rf.render(_ico(), **_cam())             # an earlier frame of another scene
    return _of(rf.render(_torus(), **_cam(), raster=rf.RasterState(normals="smooth"), out=out))


def case_render_out_reusable():
    import refraster as rf
    out = rf.Framebuffer.reusable(96, 72)
    rf.render(_ico(), **_cam(), out=out)          # the frame before: clears its spans
    return _of(rf.render(_open_torus(), **_cam(), raster=rf.RasterState(cull="back"), out=out))


def case_render_many_options():
    import refraster as rf
    return _of(rf.render([_torus(), _cube()], **_cam(128, 96),
                         raster=rf.RasterState(normals="smooth", cull="front",
                                               depth_func="gequal", clear_depth=0.0,
                                               precision="float64", subpixel_bits=4,
                                               fill_rule="bottom-left"),
                         model=[_turn(0.3, [0, 1, 0]), _shift(0.2, -0.1, 0.1)],
                         background=(0.0, 0.0, 0.0)))


# RasterState fields the old keywords did not have: recorded on the new API (--add), not at
# a469114


def case_render_front_face_cw():
    """Clockwise front faces, nothing culled: :func:`case_render_open_torus` with
    ``front_facing`` turned over (the only output that differs)."""
    import refraster as rf
    return _of(rf.render(_open_torus(), **_cam(), raster=rf.RasterState(front_face="cw")))


def case_render_front_face_cw_cull_back():
    """Clockwise front faces, the back culled: :func:`case_render_cull_front`'s pixels, seen
    as front faces (``front_facing`` is the only output that differs)."""
    import refraster as rf
    return _of(rf.render(_open_torus(), **_cam(),
                         raster=rf.RasterState(front_face="cw", cull="back")))


def case_render_depth_write_false():
    """No depth writes on the open torus drawn twice: each fragment is tested against the
    cleared depth, so the last one drawn wins (the fragment stream's resolve)."""
    import refraster as rf
    return _of(rf.render(_twice(), **_cam(), raster=rf.RasterState(depth_write=False)))


# ============================================================================== draw, resolve,
# rasterize, Framebuffer.from_fragments
# draw defaults: model=None, raster=None (its cull, front_face, precision, subpixel_bits,
# fill_rule); resolve: raster=None (its depth_func, depth_write, clear_depth), keep=None;
# rasterize: raster=None (its cull, front_face, subpixel_bits, fill_rule);
# Framebuffer.from_fragments: raster=None (its normals), background=(1, 1, 1)


def _two_draws():
    import refraster as rf
    return rf.draw([_torus(), _ico()], **_cam(), model=[np.eye(4), _shift(0.3, 0.0, 0.2)])


def _dup_draws():
    """The open torus, the sphere and the open torus again: ties at equal depth for the
    depth functions."""
    import refraster as rf
    return rf.draw([_open_torus(), _ico(), _open_torus()], **_cam(),
                   model=[np.eye(4), _shift(0.3, 0.0, 0.2), np.eye(4)])


def case_draw_defaults():
    import refraster as rf
    return _frags(rf.draw(_torus(), **_cam()))


def case_draw_model_list():
    return _frags(_two_draws())


def case_draw_model_one():
    import refraster as rf
    return _frags(rf.draw(_torus(), **_cam(), model=_turn(0.5, [0, 0, 1])))


def case_draw_cull_back():
    import refraster as rf
    return _frags(rf.draw(_open_torus(), **_cam(), raster=rf.RasterState(cull="back")))


def case_draw_cull_front():
    import refraster as rf
    return _frags(rf.draw(_open_torus(), **_cam(), raster=rf.RasterState(cull="front")))


def case_draw_precision_float64():
    import refraster as rf
    return _frags(rf.draw(_torus(), **_cam(), raster=rf.RasterState(precision="float64")))


def case_draw_subpixel_bits_4():
    import refraster as rf
    return _frags(rf.draw(_torus(), **_cam(), raster=rf.RasterState(subpixel_bits=4)))


def case_draw_ties():
    import refraster as rf
    return _frags(rf.draw(_ties(), **_tie_cam()))


def case_draw_fill_rule_top_left():
    import refraster as rf
    return _frags(rf.draw(_ties(), **_tie_cam(), raster=rf.RasterState(fill_rule="top-left")))


def case_draw_fill_rule_bottom_left():
    import refraster as rf
    return _frags(rf.draw(_ties(), **_tie_cam(), raster=rf.RasterState(fill_rule="bottom-left")))


def case_draw_interpolate():
    fr = _two_draws()
    return {"world": fr.world_position(), "eye": fr.eye_position(),
            "object": fr.object_position(), "attr": fr.interpolate([_torus()[0], _ico()[0]])}


def case_resolve_defaults():
    import refraster as rf
    return _of(rf.resolve(_dup_draws()))


def case_resolve_depth_func_lequal():
    import refraster as rf
    return _of(rf.resolve(_dup_draws(), raster=rf.RasterState(depth_func="lequal")))


def case_resolve_depth_func_greater():
    import refraster as rf
    return _of(rf.resolve(_dup_draws(),
                          raster=rf.RasterState(depth_func="greater", clear_depth=0.0)))


def case_resolve_depth_func_gequal():
    import refraster as rf
    return _of(rf.resolve(_dup_draws(),
                          raster=rf.RasterState(depth_func="gequal", clear_depth=0.0)))


def case_resolve_depth_func_equal():
    import refraster as rf
    fr = _two_draws()
    return _of(rf.resolve(fr, raster=rf.RasterState(depth_func="equal",
                                                    clear_depth=float(fr.depth[len(fr) // 2]))))


def case_resolve_depth_func_notequal():
    import refraster as rf
    return _of(rf.resolve(_dup_draws(), raster=rf.RasterState(depth_func="notequal")))


def case_resolve_depth_func_always():
    import refraster as rf
    return _of(rf.resolve(_dup_draws(), raster=rf.RasterState(depth_func="always")))


def case_resolve_depth_func_never():
    import refraster as rf
    return _of(rf.resolve(_dup_draws(), raster=rf.RasterState(depth_func="never")))


def case_resolve_depth_write_false():
    import refraster as rf
    return _of(rf.resolve(_dup_draws(), raster=rf.RasterState(depth_write=False)))


def case_resolve_keep():
    import refraster as rf
    fr = _two_draws()
    return _of(rf.resolve(fr, keep=(fr.prim_id % 2 == 0)))


def case_resolve_clear_depth():
    import refraster as rf
    return _of(rf.resolve(_two_draws(), raster=rf.RasterState(clear_depth=0.7)))


def case_resolve_all_options():
    import refraster as rf
    fr = _two_draws()
    return _of(rf.resolve(fr, raster=rf.RasterState(depth_func="greater", depth_write=False,
                                                    clear_depth=0.5),
                          keep=fr.depth > 0.3))


def case_from_fragments_defaults():
    import refraster as rf
    fr = _two_draws()
    return _of(rf.Framebuffer.from_fragments(fr, rf.resolve(fr)))


def case_from_fragments_options():
    import refraster as rf
    fr = _two_draws()
    return _of(rf.Framebuffer.from_fragments(
        fr, rf.resolve(fr, raster=rf.RasterState(depth_func="lequal")),
        raster=rf.RasterState(normals="smooth"), background=(0.3, 0.3, 0.1)))


def _clip_of_torus(mesh=None, w=96, h=72):
    cam = _cam(w, h)
    v, f = _torus() if mesh is None else mesh
    clip = np.c_[v, np.ones(len(v))] @ (cam["proj"] @ cam["view"]).T
    return clip, f


def case_rasterize_defaults():
    import refraster as rf
    return _frags(rf.rasterize(*_clip_of_torus(), 96, 72))


def case_rasterize_float32_clip():
    import refraster as rf
    clip, f = _clip_of_torus()
    return _frags(rf.rasterize(clip.astype(np.float32), f, 96, 72))


def case_rasterize_cull_back():
    import refraster as rf
    return _frags(rf.rasterize(*_clip_of_torus(_open_torus()), 96, 72,
                               raster=rf.RasterState(cull="back")))


def case_rasterize_cull_front():
    import refraster as rf
    return _frags(rf.rasterize(*_clip_of_torus(_open_torus()), 96, 72,
                               raster=rf.RasterState(cull="front")))


def case_rasterize_subpixel_bits_4():
    import refraster as rf
    return _frags(rf.rasterize(*_clip_of_torus(), 96, 72, raster=rf.RasterState(subpixel_bits=4)))


def _clip_of_ties():
    cam = _tie_cam()
    v, f = _ties()
    return np.c_[v, np.ones(len(v))] @ (cam["proj"] @ cam["view"]).T, f


def case_rasterize_ties():
    import refraster as rf
    return _frags(rf.rasterize(*_clip_of_ties(), 64, 48))


def case_rasterize_fill_rule_top_left():
    import refraster as rf
    return _frags(rf.rasterize(*_clip_of_ties(), 64, 48,
                               raster=rf.RasterState(fill_rule="top-left")))


def case_rasterize_fill_rule_bottom_left():
    import refraster as rf
    return _frags(rf.rasterize(*_clip_of_ties(), 64, 48,
                               raster=rf.RasterState(fill_rule="bottom-left")))


# ============================================================================== refraster.ldi
# peel defaults: max_layers=None, mode="peel", model=None, raster=None (its cull,
# front_face, precision, subpixel_bits, fill_rule); peel_fragments: max_layers=None,
# mode="peel"; VolumetricDepthSprite.from_mesh: resolution=256, axis="z", margin=2,
# strict=False, raster=None (its precision); contains / fragment_stage: rule="parity"


def _peel_scene():
    return [_torus(), _ico(), _ico()]          # the last two coincide: "peel" merges them


def _peel_models():
    return [np.eye(4), _shift(0.2, 0.0, 0.1), _shift(0.2, 0.0, 0.1)]


def case_ldi_peel_defaults():
    from refraster import ldi
    return _of(ldi.peel(_peel_scene(), **_cam(), model=_peel_models()))


def case_ldi_peel_max_layers():
    from refraster import ldi
    return _of(ldi.peel(_peel_scene(), **_cam(), model=_peel_models(), max_layers=2))


def case_ldi_peel_mode_all():
    from refraster import ldi
    return _of(ldi.peel(_peel_scene(), **_cam(), model=_peel_models(), mode="all"))


def case_ldi_peel_model_one():
    from refraster import ldi
    return _of(ldi.peel(_torus(), **_cam(), model=_turn(0.4, [1, 0, 0])))


def case_ldi_peel_cull_back():
    from refraster import RasterState, ldi
    return _of(ldi.peel(_open_torus(), **_cam(), raster=RasterState(cull="back")))


def case_ldi_peel_cull_front():
    from refraster import RasterState, ldi
    return _of(ldi.peel(_open_torus(), **_cam(), raster=RasterState(cull="front")))


def case_ldi_peel_precision_float64():
    from refraster import RasterState, ldi
    return _of(ldi.peel(_torus(), **_cam(), raster=RasterState(precision="float64")))


def case_ldi_peel_subpixel_bits_4():
    from refraster import RasterState, ldi
    return _of(ldi.peel(_torus(), **_cam(), raster=RasterState(subpixel_bits=4)))


def case_ldi_peel_fill_rule_top_left():
    from refraster import RasterState, ldi
    return _of(ldi.peel(_ties(), **_tie_cam(), raster=RasterState(fill_rule="top-left")))


def case_ldi_peel_fill_rule_bottom_left():
    from refraster import RasterState, ldi
    return _of(ldi.peel([_ties(), _ties()], **_tie_cam(),
                        raster=RasterState(fill_rule="bottom-left"), mode="all"))


def case_ldi_peel_fragments_defaults():
    from refraster import ldi
    return _of(ldi.peel_fragments(_two_draws()))


def case_ldi_peel_fragments_max_layers():
    from refraster import ldi
    return _of(ldi.peel_fragments(_two_draws(), max_layers=1))


def case_ldi_peel_fragments_mode_all():
    from refraster import ldi
    return _of(ldi.peel_fragments(_two_draws(), mode="all"))


def case_ldi_peel_fragments_rasterized():
    import refraster as rf
    from refraster import ldi
    return _of(ldi.peel_fragments(rf.rasterize(*_clip_of_torus(), 96, 72), max_layers=3,
                                  mode="all"))


@functools.cache
def _shells():
    from refraster import scenes
    return _arrays(scenes.nested_shells((0.6, 0.45, 0.3, 0.2), subdivisions=2))


def case_ldi_vds_defaults():
    from refraster.ldi import VolumetricDepthSprite
    return _sprite(VolumetricDepthSprite.from_mesh(_shells()))


def case_ldi_vds_resolution():
    from refraster.ldi import VolumetricDepthSprite
    return _sprite(VolumetricDepthSprite.from_mesh(_shells(), resolution=40))


def case_ldi_vds_axis_x():
    from refraster.ldi import VolumetricDepthSprite
    return _sprite(VolumetricDepthSprite.from_mesh(_shells(), resolution=40, axis="x"))


def case_ldi_vds_axis_y():
    from refraster.ldi import VolumetricDepthSprite
    return _sprite(VolumetricDepthSprite.from_mesh(_shells(), resolution=40, axis="y"))


def case_ldi_vds_axis_xyz():
    from refraster.ldi import VolumetricDepthSprite
    return _sprite(VolumetricDepthSprite.from_mesh(_shells(), resolution=40, axis="xyz"))


def case_ldi_vds_margin():
    from refraster.ldi import VolumetricDepthSprite
    return _sprite(VolumetricDepthSprite.from_mesh(_shells(), resolution=40, margin=5))


def case_ldi_vds_strict():
    """strict=True: an open box raises instead of warning (its message is the output)."""
    from refraster.ldi import VolumetricDepthSprite
    v, f = _box()
    try:
        VolumetricDepthSprite.from_mesh((v, f[:-1]), resolution=32, axis="xyz", strict=True)
    except ValueError as exc:
        return {"error": str(exc)}
    return {"error": None}


def case_ldi_vds_precision_float64():
    from refraster import RasterState
    from refraster.ldi import VolumetricDepthSprite
    return _sprite(VolumetricDepthSprite.from_mesh(_shells(), resolution=40,
                                                   raster=RasterState(precision="float64")))


def case_ldi_vds_not_watertight():
    """An open box: the warning's text and the sprite with odd counts."""
    from refraster.ldi import VolumetricDepthSprite
    v, f = _box()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = VolumetricDepthSprite.from_mesh((v, f[:-1]), resolution=32, axis="xyz")
    return {"warnings": [str(w.message) for w in caught], **_sprite(s)}


def case_ldi_vds_fragment_stage():
    import refraster as rf
    from refraster.ldi import VolumetricDepthSprite
    s = VolumetricDepthSprite.from_mesh(_shells(), resolution=40)
    plane = (np.array([[-1, -1, 0.05], [1, -1, 0.05], [1, 1, 0.05], [-1, 1, 0.05]]),
             np.array([[0, 1, 2], [0, 2, 3]]))
    return {"parity": _of(rf.render(plane, **_cam(), fragment_stage=s.fragment_stage())),
            "nonzero": _of(rf.render(plane, **_cam(),
                                     fragment_stage=s.fragment_stage(rule="nonzero")))}


def case_ldi_parity_at():
    """The per-point kernel on the packed LDIs of a three-axis sprite, both rules."""
    from refraster.ldi import VolumetricDepthSprite, parity_at
    s = VolumetricDepthSprite.from_mesh(_shells(), resolution=40, axis="xyz")
    mats, depth, sign, count, start, cstart, shape = s.packed()
    pts = _grid_points()[::7]
    out = np.zeros((len(mats), 2, len(pts)), np.bool_)
    for k in range(len(mats)):
        for rule in (0, 1):
            for i, p in enumerate(pts):
                out[k, rule, i] = parity_at(p[0], p[1], p[2], mats[k], depth, sign, count,
                                            start[k], cstart[k], shape[k, 0], shape[k, 1],
                                            bool(rule))
    return {"parity_at": out}


# ============================================================================== render_clipped
# defaults: caps=Caps() (style="diffuse", mode="mesh", color=(0.80, 0.30, 0.25),
# hatch_spacing=None, texture_frequency=4.0, subdivision=1, occlusion_radius=None,
# solid_texture=None, vds_resolution=1024; caps=None: no caps), space="world", model=None,
# normals=None, cull="none", precision="float32", vds=None, background=(1, 1, 1)


def _surface(**kw):
    from refraster.clipsurface import ClipSurface
    from refraster.clipsurface import offsetmaps as om
    return ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.3), om.perlin_noise(16),
                       **kw)


def _ccam():
    import refraster as rf
    return dict(view=rf.look_at([1.5, 1.2, 2.2], [0, 0, 0]),
                proj=rf.perspective(35, 4 / 3, 0.5, 10), width=80, height=60)


@functools.cache
def _box_sprite():
    from refraster.ldi import VolumetricDepthSprite
    return VolumetricDepthSprite.from_mesh(_box(), resolution=64)


@functools.cache
def _ico_sprite():
    from refraster.ldi import VolumetricDepthSprite
    return VolumetricDepthSprite.from_mesh(_ico(), resolution=40)


class _BoxContains:
    """A duck-typed parity test (not a sprite): render_clipped's fragment-stream path."""

    def contains(self, p):
        return np.all(np.abs(p) <= 0.5, axis=1)


def case_clip_defaults():
    from refraster.clipsurface import render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam()))


def case_clip_vds_resolution_64():
    """The sprite's resolution the other box cases use (64): what their options differ
    from."""
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), caps=Caps(vds_resolution=64)))


def case_clip_caps_false():
    """No caps (once ``caps=False``): ``caps=None``."""
    from refraster.clipsurface import render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), caps=None))


def case_clip_cap_style_hatch():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="hatch", vds_resolution=64)))


def case_clip_cap_style_marble():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="marble", vds_resolution=64)))


def case_clip_cap_style_wood():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="wood", vds_resolution=64)))


def case_clip_cap_style_noise():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="noise", vds_resolution=64)))


def _volume():
    i, j, k = np.meshgrid(np.arange(6), np.arange(5), np.arange(4), indexing="ij")
    return np.stack([(i / 5.0), (j / 4.0), ((i + j + k) % 3) / 2.0], -1).astype(np.float32)


def case_clip_cap_style_solid_array():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="solid", solid_texture=_volume(),
                                        vds_resolution=64)))


def case_clip_cap_style_solid_texture():
    from refraster.clipsurface import Caps, render_clipped
    from refraster.clipsurface.textures import SolidTexture
    tex = SolidTexture(_volume()[..., 0], origin=(-0.5, -0.5, -0.5), size=(0.7, 0.6, 0.5),
                       wrap="mirrored_repeat")
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="solid", solid_texture=tex, vds_resolution=64),
                              model=_shift(0.1, 0, 0)))


def case_clip_cap_mode_exact():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(mode="exact", vds_resolution=64)))


def case_clip_cap_mode_exact_hatch_duck():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), vds=[_BoxContains()],
                              caps=Caps(style="hatch", mode="exact", hatch_spacing=0.05)))


def case_clip_cap_color():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(color=(0.1, 0.6, 0.9), vds_resolution=64)))


def case_clip_hatch_spacing():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="hatch", color=(0.0, 0.2, 0.0),
                                        hatch_spacing=0.04, vds_resolution=64)))


def case_clip_texture_frequency():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(style="marble", texture_frequency=9.0, vds_resolution=64)))


def _scaled_view():
    """A view with a uniform scale 2: not rigid, so the eye-space clip test differs from the
    world-space one (for a rigid view they agree but for rounding)."""
    return dict(_ccam(), view=np.diag([2.0, 2.0, 2.0, 1.0]) @ _ccam()["view"])


def case_clip_scaled_view():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_scaled_view(), caps=Caps(vds_resolution=64)))


def case_clip_space_eye():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_scaled_view(), caps=Caps(vds_resolution=64),
                              space="eye"))


def case_clip_model():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), caps=Caps(vds_resolution=64),
                              model=_turn(0.4, [0, 1, 0]) @ _shift(0.05, 0.0, 0.0)))


def case_clip_model_list_two_solids():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped([_box(), _box()], _surface(), **_ccam(), caps=Caps(vds_resolution=64),
                              model=[_shift(-0.3, 0, 0), _shift(0.4, 0.2, -0.3)]))


def case_clip_normals_flat():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_ico(), _surface(), **_ccam(), caps=Caps(vds_resolution=64),
                              raster=RasterState(normals="flat")))


def case_clip_normals_smooth():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_ico(), _surface(), **_ccam(), caps=Caps(vds_resolution=64),
                              raster=RasterState(normals="smooth")))


def case_clip_cull_back():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(vds_resolution=64), raster=RasterState(cull="back")))


def case_clip_cull_front():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(vds_resolution=64), raster=RasterState(cull="front")))


def case_clip_precision_float64():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), caps=Caps(vds_resolution=64),
                              raster=RasterState(precision="float64")))


def case_clip_subdivision_2():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(subdivision=2, vds_resolution=64)))


def case_clip_ico_defaults():
    """A curved solid: its caps depend on the sprite's resolution (the default 1024 here)."""
    from refraster.clipsurface import render_clipped
    return _of(render_clipped(_ico(), _surface(), **_ccam()))


def case_clip_vds_sprite():
    from refraster.clipsurface import render_clipped
    return _of(render_clipped(_ico(), _surface(), **_ccam(), vds=[_ico_sprite()]))


def case_clip_vds_duck():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), vds=[_BoxContains()],
                              caps=Caps(style="wood")))


def case_clip_vds_resolution():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_ico(), _surface(), **_ccam(), caps=Caps(vds_resolution=16)))


def case_clip_occlusion_radius():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(),
                              caps=Caps(occlusion_radius=0.08, vds_resolution=64)))


def case_clip_background():
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), caps=Caps(vds_resolution=64),
                              background=(0.2, 0.3, 0.4)))


def case_clip_exact_options():
    """Exact caps with the options their path reads: eye space, model, colour, occlusion,
    normals, cull, precision, background, a solid texture."""
    from refraster.clipsurface import Caps, render_clipped
    return _of(render_clipped(_box(), _surface(), **_ccam(), vds=[_box_sprite()],
                              caps=Caps(style="solid", mode="exact", color=(0.3, 0.3, 0.9),
                                        occlusion_radius=0.1, solid_texture=_volume()),
                              space="eye", raster=RasterState(normals="smooth", cull="back", precision="float64"),
                              background=(0, 0, 0)))


def case_clip_cap_textures():
    """A surface with its own diffuse, normal and light maps (CapTextures)."""
    from refraster.clipsurface import Caps, render_clipped
    from refraster.clipsurface.textures import CapTextures
    y, x = np.mgrid[0:8, 0:8] / 7.0
    diffuse = np.stack([x, y, 0.5 * (x + y)], -1)
    normal = np.stack([0.5 + 0.2 * x, 0.5 + 0.1 * y, np.ones_like(x)], -1)
    tex = CapTextures(diffuse=diffuse, normal=normal, light=0.5 + 0.5 * x)
    return _of(render_clipped(_box(), _surface(textures=tex), **_ccam(),
                              caps=Caps(vds_resolution=64)))


def case_clip_two_surfaces_one_disabled():
    from refraster.clipsurface import Caps, ClipSurface, render_clipped
    from refraster.clipsurface import offsetmaps as om
    other = ClipSurface([0.1, 0, 0], [0, 0, 1.5], [0, 1.5, 0], (2, 2, 0.2), om.sinusoid(16),
                        wrap="clamp_to_edge")
    off = _surface(enabled=False)
    return _of(render_clipped(_box(), [_surface(), other, off], **_ccam(),
                              caps=Caps(style="hatch", vds_resolution=64)))


def case_clip_relief_plane():
    from refraster.clipsurface import Caps, ReliefClipPlane, render_clipped
    from refraster.clipsurface import offsetmaps as om
    rcp = ReliefClipPlane([0.3, 0.2, 1.0], [0, 0, 0.05], om.value_noise(16), 0.1)
    return _of(render_clipped(_box(), rcp, **_ccam(), caps=Caps(vds_resolution=64)))


# ============================================================================== render_cutaway
# defaults: stand_ins=(), cutaway=Cutaway() (angle=π/6, variant="jfa",
# perspective_compensation=True, edge_compression=0.1, floor_normal=None,
# floor_margin=FLOOR_MARGIN, buffer_size=None), cut_surfaces=CutSurfaces() (shade=True,
# color=None, dilation=True, outlines=True), ghosts=GhostLines() (source="lines",
# distance=None, fade=True, crease_angle=GHOST_CREASE_ANGLE; ghosts=None: no ghost lines),
# normals=None, background=(1, 1, 1)


@functools.cache
def _cut_scene():
    from refraster.scenes import icosphere, nested_shells
    c = _cube()
    lo, hi = np.array([0.25, -0.15, 0.1]), np.array([0.5, 0.15, 0.4])
    block = ((c[0] + 0.5) * (hi - lo) + lo, c[1])
    return (_arrays(nested_shells((1.2, 1.0, 0.75, 0.6), subdivisions=2)),
            [_arrays(icosphere(2, radius=0.3)), block])


def _kcam(w=96, h=80, eye=(2.5, 1.2, 3.0)):
    import refraster as rf
    return dict(view=rf.look_at(list(eye), (0, 0, 0)), proj=rf.perspective(40, w / h, 1.0, 12.0),
                width=w, height=h)


def _kcam2():
    """The view in which the jump-flood variants and the exact distance differ."""
    return _kcam(eye=(-3.2, 0.4, 1.5))


def _edge_stand_in():
    """A small stand-in seen near the top border of :func:`_kcam2`'s frame (NDC y ≈ 0.93),
    inside the shells: its seeds are within the edge-compression band."""
    from refraster.scenes import icosphere
    m = icosphere(1, radius=0.08)
    return np.asarray(m.vertices) + [0.04, 1.16, 0.15], np.asarray(m.faces)


def _crate():
    c = _cube()
    return ((c[0] + 0.5) * 1.6 - 0.8, c[1])


def case_cut_defaults():
    from refraster.cutaway import render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam()))


def case_cut_angle():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), cutaway=Cutaway(angle=0.5)))


def case_cut_angle_list():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), cutaway=Cutaway(angle=[0.4, 0.8])))


def case_cut_stand_ins():
    from refraster.cutaway import render_cutaway
    from refraster.scenes import icosphere
    shells, core = _cut_scene()
    return _of(render_cutaway([], shells, **_kcam(), stand_ins=[icosphere(1, radius=0.3)]))


def case_cut_stand_ins_with_interest_angles():
    from refraster.cutaway import Cutaway, render_cutaway
    from refraster.scenes import icosphere
    shells, core = _cut_scene()
    m = icosphere(1, radius=0.2)
    stand = (np.asarray(m.vertices) + [-0.4, 0.3, 0.2], np.asarray(m.faces))
    return _of(render_cutaway(core[:1], shells, **_kcam(), stand_ins=[stand],
                              cutaway=Cutaway(angle=[0.5, 0.3])))


def case_cut_cutaway_size():
    """The cutaway buffer's size (once ``cutaway_size=``): ``Cutaway(buffer_size=...)``."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), cutaway=Cutaway(buffer_size=(48, 40))))


def case_cut_view2():
    """The default variant ("jfa", the paper's) in the second view; until issue 46 the default
    was "jfa+1" (:func:`case_cut_variant_jfa1` keeps that digest)."""
    from refraster.cutaway import render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2()))


def case_cut_variant_jfa():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), cutaway=Cutaway(variant="jfa")))



def case_cut_variant_jfa1():
    """``cut_view2`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), cutaway=Cutaway(variant="jfa+1")))


def case_cut_variant_jfa2():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), cutaway=Cutaway(variant="jfa+2")))


def case_cut_variant_1jfa():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), cutaway=Cutaway(variant="1+jfa")))


def case_cut_variant_exact():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), cutaway=Cutaway(variant="exact")))


def case_cut_perspective_compensation_false():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(),
                              cutaway=Cutaway(perspective_compensation=False)))


def case_cut_perspective_compensation_false_jfa1():
    """``cut_perspective_compensation_false`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(),
                              cutaway=Cutaway(variant="jfa+1", perspective_compensation=False)))


def case_cut_edge_stand_in():
    """The default edge compression (0.1) acting on a stand-in near the border."""
    from refraster.cutaway import render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()]))


def case_cut_edge_stand_in_jfa1():
    """``cut_edge_stand_in`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()],
                              cutaway=Cutaway(variant="jfa+1")))


def case_cut_edge_compression_none():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()],
                              cutaway=Cutaway(edge_compression=None)))


def case_cut_edge_compression_none_jfa1():
    """``cut_edge_compression_none`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()],
                              cutaway=Cutaway(variant="jfa+1", edge_compression=None)))


def case_cut_edge_compression_zero():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()],
                              cutaway=Cutaway(edge_compression=0.0)))


def case_cut_edge_compression_zero_jfa1():
    """``cut_edge_compression_zero`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()],
                              cutaway=Cutaway(variant="jfa+1", edge_compression=0.0)))


def case_cut_edge_compression_value():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()],
                              cutaway=Cutaway(edge_compression=0.35)))


def case_cut_edge_compression_value_jfa1():
    """``cut_edge_compression_value`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), stand_ins=[_edge_stand_in()],
                              cutaway=Cutaway(variant="jfa+1", edge_compression=0.35)))


def case_cut_floor_normal():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), cutaway=Cutaway(floor_normal=(0, 1, 0))))


def case_cut_floor_margin():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(),
                              cutaway=Cutaway(floor_normal=(0.1, 1, 0), floor_margin=0.2)))


def case_cut_floor_margin_jfa1():
    """``cut_floor_margin`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(),
                              cutaway=Cutaway(variant="jfa+1", floor_normal=(0.1, 1, 0),
                                              floor_margin=0.2)))


def case_cut_floor_view2():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(), cutaway=Cutaway(floor_normal=(0, 1, 0))))


def case_cut_floor_view2_jfa1():
    """``cut_floor_view2`` with ``"jfa+1"`` (its digest before issue 46)."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(),
                              cutaway=Cutaway(variant="jfa+1", floor_normal=(0, 1, 0))))


def case_cut_floor_exact():
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam2(),
                              cutaway=Cutaway(variant="exact", floor_normal=(0, 1, 0))))


def case_cut_dilation_false():
    from refraster.cutaway import CutSurfaces, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), cut_surfaces=CutSurfaces(dilation=False)))


def case_cut_outlines_false():
    from refraster.cutaway import CutSurfaces, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), cut_surfaces=CutSurfaces(outlines=False)))


def case_cut_ghost_distance_zero():
    """No ghost lines (once ``ghost_distance=0``): ``ghosts=None``."""
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, _crate(), **_kcam(eye=(2.5, 2.0, 3.0)),
                              cutaway=Cutaway(angle=0.6), ghosts=None))


def case_cut_ghost_distance_value():
    from refraster.cutaway import Cutaway, GhostLines, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, _crate(), **_kcam(eye=(2.5, 2.0, 3.0)),
                              cutaway=Cutaway(angle=0.6), ghosts=GhostLines(distance=2.0)))


def case_cut_cut_color():
    from refraster.cutaway import CutSurfaces, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(),
                              cut_surfaces=CutSurfaces(color=(0.9, 0.2, 0.1))))


def case_cut_normals_smooth():
    from refraster.cutaway import render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), raster=RasterState(normals="smooth")))


def case_cut_background():
    from refraster.cutaway import render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), background=(0.1, 0.1, 0.2)))


def case_cut_ghost_visible():
    from refraster.cutaway import Cutaway, GhostLines, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, _crate(), **_kcam(eye=(2.5, 2.0, 3.0)),
                              cutaway=Cutaway(angle=0.6),
                              ghosts=GhostLines(source="visible", distance=2.0)))


def case_cut_ghost_visible_no_fade():
    from refraster.cutaway import Cutaway, GhostLines, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, _crate(), **_kcam(eye=(2.5, 2.0, 3.0)),
                              cutaway=Cutaway(angle=0.6),
                              ghosts=GhostLines(source="visible", distance=2.0, fade=False),
                              raster=RasterState(normals="smooth")))


def case_cut_ghost_fade_false():
    from refraster.cutaway import Cutaway, GhostLines, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, _crate(), **_kcam(eye=(2.5, 2.0, 3.0)),
                              cutaway=Cutaway(angle=0.6),
                              ghosts=GhostLines(distance=2.0, fade=False)))


def case_cut_crease_angle():
    from refraster.cutaway import GhostLines, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(),
                              ghosts=GhostLines(distance=1.0, crease_angle=5.0)))


def case_cut_cut_surfaces_false():
    """Cut surfaces left as drawn (once ``cut_surfaces=False``): ``CutSurfaces(shade=False)``."""
    from refraster.cutaway import CutSurfaces, render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway(core, shells, **_kcam(), cut_surfaces=CutSurfaces(shade=False)))


def case_cut_orthographic():
    import refraster as rf
    from refraster.cutaway import Cutaway, render_cutaway
    shells, core = _cut_scene()
    cam = dict(_kcam(), proj=rf.orthographic(-1.6, 1.6, -1.33, 1.33, 1.0, 12.0))
    return _of(render_cutaway(core, shells, **cam,
                              cutaway=Cutaway(angle=0.7, floor_normal=(0, 1, 0))))


def case_cut_no_interest():
    from refraster.cutaway import render_cutaway
    shells, core = _cut_scene()
    return _of(render_cutaway([], shells, **_kcam()))


# ============================================================================== render_halos
# defaults: view=View4D() (rotation=None, projection="orthographic", eye=None, scale=1.0,
# margin=0.05, stereo=None), width=512, height=512, slices=256, halos=Halos() (enabled=True,
# rho=None, delta_d=None, delta_t=0.3, surface_width=0.3, antialias=None, depth_eps=None),
# style=HaloStyle() (opacity=0.9, ambient=0.3, halo_color=(0.5, 0.5, 0.5), halo_opacity=0.0,
# boundary_color=None, boundary_width=0.15), background=(0, 0, 0), volume=False,
# engine="fused"


@functools.cache
def _fig1():
    import refraster.halos4d as h
    return h.figure1_scene(8)


def _hkw():
    """Every case: a small frame and few slices (width, height, slices away from default)."""
    return dict(width=48, height=40, slices=12)


def _hrot():
    import refraster.halos4d as h
    return h.compose(("zx", 0.5), ("yz", -0.6))


def case_halo_small():
    from refraster.halos4d import render_halos
    return _of(render_halos(_fig1(), **_hkw()))


def case_halo_rotation():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot())))


def case_halo_perspective():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(),
                            view=View4D(rotation=_hrot(), projection="perspective")))


def case_halo_perspective_eye_scale():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(),
                            view=View4D(rotation=_hrot(), projection="perspective", eye=6.0,
                                        scale=1.5)))


def case_halo_orthographic_scale():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot(), scale=0.7)))


def case_halo_slices():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), width=48, height=40, slices=5,
                            view=View4D(rotation=_hrot())))


def case_halo_size():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), width=64, height=30, slices=12,
                            view=View4D(rotation=_hrot())))


def case_halo_rho():
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(rho=0.08)))


def case_halo_delta_d():
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(delta_d=0.6)))


def case_halo_delta_t():
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(delta_t=0.15)))


def case_halo_surface_width():
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(surface_width=0.5)))


def case_halo_opacity():
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            style=HaloStyle(opacity=0.6)))


def case_halo_opacity_one():
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            style=HaloStyle(opacity=1.0)))


def case_halo_halos_false():
    """Without halos (once ``halos=False``): ``Halos(enabled=False)``."""
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(enabled=False)))


def case_halo_background():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            background=(1.0, 0.9, 0.8)))


def case_halo_depth_eps():
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(depth_eps=0.05)))


def case_halo_margin():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot(), margin=0.3)))


def case_halo_stereo():
    """The stereo pair at the default angle (once ``stereo=True``): ``View4D(stereo=6.0)``."""
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot(), stereo=6.0)))


def case_halo_stereo_angle():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot(), stereo=15.0)))


def case_halo_volume():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), volume=True))


def case_halo_engine_reference():
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), engine="reference"))


def case_halo_engine_reference_volume_options():
    from refraster.halos4d import HaloStyle, Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), engine="reference",
                            volume=True, halos=Halos(antialias=0.15),
                            style=HaloStyle(halo_opacity=0.3, boundary_color=(0, 1, 0))))


def case_halo_engine_fused_explicit():
    from refraster.halos4d import HaloStyle, Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), engine="fused",
                            volume=True, halos=Halos(antialias=0.15),
                            style=HaloStyle(halo_opacity=0.3, boundary_color=(0, 1, 0))))


def case_halo_halo_color():
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            style=HaloStyle(halo_color=(0.9, 0.1, 0.1), halo_opacity=0.4)))


def case_halo_halo_opacity():
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            style=HaloStyle(halo_opacity=0.5)))


def case_halo_boundary_color():
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            style=HaloStyle(boundary_color=(0, 1, 0))))


def case_halo_boundary_width():
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            style=HaloStyle(boundary_color=(0, 1, 0), boundary_width=0.4)))


def case_halo_antialias_zero():
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(antialias=0.0)))


def case_halo_antialias_value():
    from refraster.halos4d import Halos, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            halos=Halos(antialias=0.1)))


def case_halo_ambient():
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                            style=HaloStyle(ambient=0.7)))


def case_halo_pair():
    from refraster.halos4d import View4D, render_halos_pair
    on, off = render_halos_pair(_fig1(), **_hkw(), view=View4D(rotation=_hrot()))
    return {"on": _of(on), "off": _of(off)}


def case_halo_pair_options():
    from refraster.halos4d import HaloStyle, Halos, View4D, render_halos_pair
    on, off = render_halos_pair(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                                halos=Halos(delta_d=0.5, antialias=0.0),
                                style=HaloStyle(halo_opacity=0.3, boundary_color=(0, 1, 0)),
                                background=(1, 1, 1))
    return {"on": _of(on), "off": _of(off)}


def case_halo_pair_volume_reference():
    from refraster.halos4d import HaloStyle, View4D, render_halos_pair
    on, off = render_halos_pair(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), volume=True,
                                engine="reference", style=HaloStyle(halo_opacity=0.3))
    return {"on": _of(on), "off": _of(off)}


def case_halo_pair_stereo():
    from refraster.halos4d import HaloStyle, View4D, render_halos_pair
    on, off = render_halos_pair(_fig1(), **_hkw(), view=View4D(rotation=_hrot(), stereo=10.0),
                                style=HaloStyle(boundary_color=(0, 1, 0)))
    return {"on": _of(on), "off": _of(off)}


# halos.split="global_index": the split of the releases before issue 46 (the default became the
# paper's repair); each case is an older case with that field, and has that case's digests of
# before the change (benchmarks/entry_digests.json at 47cc54b)
def _gi(**kw):
    from refraster.halos4d import Halos
    return Halos(split="global_index", **kw)


def case_halo_split_global_index_small():
    """``halo_small``'s digests of 47cc54b."""
    from refraster.halos4d import render_halos
    return _of(render_halos(_fig1(), **_hkw(), halos=_gi()))


def case_halo_split_global_index():
    """``halo_rotation``'s digests of 47cc54b."""
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), halos=_gi()))


def case_halo_split_global_index_perspective():
    """``halo_perspective``'s digests of 47cc54b."""
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), halos=_gi(),
                            view=View4D(rotation=_hrot(), projection="perspective")))


def case_halo_split_global_index_stereo():
    """``halo_stereo``'s digests of 47cc54b."""
    from refraster.halos4d import View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot(), stereo=6.0),
                            halos=_gi()))


def case_halo_split_global_index_fused_volume_options():
    """``halo_engine_fused_explicit``'s digests of 47cc54b."""
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), engine="fused",
                            volume=True, halos=_gi(antialias=0.15),
                            style=HaloStyle(halo_opacity=0.3, boundary_color=(0, 1, 0))))


def case_halo_split_global_index_reference_volume_options():
    """``halo_engine_reference_volume_options``' digests of 47cc54b."""
    from refraster.halos4d import HaloStyle, View4D, render_halos
    return _of(render_halos(_fig1(), **_hkw(), view=View4D(rotation=_hrot()), engine="reference",
                            volume=True, halos=_gi(antialias=0.15),
                            style=HaloStyle(halo_opacity=0.3, boundary_color=(0, 1, 0))))


def case_halo_split_global_index_pair():
    """``halo_pair_options``' digests of 47cc54b."""
    from refraster.halos4d import HaloStyle, View4D, render_halos_pair
    on, off = render_halos_pair(_fig1(), **_hkw(), view=View4D(rotation=_hrot()),
                                halos=_gi(delta_d=0.5, antialias=0.0),
                                style=HaloStyle(halo_opacity=0.3, boundary_color=(0, 1, 0)),
                                background=(1, 1, 1))
    return {"on": _of(on), "off": _of(off)}


# ============================================================================== render_mirrored
# defaults: models=None, style=None, light=DEFAULT_LIGHT, normals="smooth",
# mirror_style=MirrorStyle() (reflectance=0.85, mirror_color=(0.85, 0.88, 0.92),
# inner_color=(1, 1, 1), profile_color=(0, 0, 0)), edge_options=None, background=(1, 1, 1)


@functools.cache
def _mirror_scene():
    import trimesh
    import refraster as rf
    torus = rf.mesh.as_mesh(trimesh.creation.torus(0.6, 0.22, major_sections=32,
                                                   minor_sections=12)).with_smooth_normals(60)
    model = np.eye(4)
    model[:3, :3] = _turn(1.1, [1, 0, 0])[:3, :3]
    model[1, 3] = 0.9
    floor = (np.array([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2.0]]),
             np.array([[0, 2, 1], [0, 3, 2]]))
    cam = dict(view=rf.look_at([2.2, 1.6, 3.0], [0.0, 0.5, 0.0]),
               proj=rf.perspective(40.0, 4 / 3, 0.5, 20.0), width=80, height=60)
    return torus, model, floor, cam


def case_mirror_defaults():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam))


def case_mirror_model():
    """The torus turned and lifted (one model matrix): what the other cases differ from."""
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model]))


def case_mirror_models():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored([torus, _box()], floor, **cam,
                                   models=[model, _shift(-0.9, 0.6, 0.4)]))


def case_mirror_style():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()

    def style(fb, light):
        return npr.hatching(fb.normal, light=light, strokes=npr.surface_strokes(fb),
                            mask=fb.mask)

    return _of(npr.render_mirrored(torus, floor, **cam, models=[model], style=style))


def case_mirror_style_toon():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model],
                                   style=lambda fb, l: npr.toon(fb.normal, light=l,
                                                                mask=fb.mask)))


def case_mirror_light():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model], light=(0.5, 1.0, 0.2)))


def case_mirror_normals_flat():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model], raster=RasterState(normals="flat")))


def case_mirror_normals_arrays():
    """Given vertex normals (once ``normals=[array]``): a ``Mesh`` with them, rendered
    ``normals="smooth"`` (the default)."""
    from refraster.edges import npr
    from refraster.mesh import Mesh
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(Mesh(torus.vertices, torus.faces, _unit(torus.vertices)),
                                   floor, **cam, models=[model]))


def case_mirror_reflectance():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model],
                                   mirror_style=npr.MirrorStyle(reflectance=0.4)))


def case_mirror_mirror_color():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model],
                                   mirror_style=npr.MirrorStyle(mirror_color=(0.2, 0.5, 0.3))))


def case_mirror_edge_options():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model],
                                   edge_options={"preset": "clean", "width": 2}))


def case_mirror_inner_color():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model],
                                   mirror_style=npr.MirrorStyle(inner_color=(0.2, 0.2, 0.9))))


def case_mirror_profile_color():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model],
                                   mirror_style=npr.MirrorStyle(profile_color=(0.8, 0.1, 0.1))))


def case_mirror_background():
    from refraster.edges import npr
    torus, model, floor, cam = _mirror_scene()
    return _of(npr.render_mirrored(torus, floor, **cam, models=[model],
                                   background=(0.0, 0.1, 0.2)))


# ============================================================================== edges and NPR
# edge_gbuffer defaults: bounds=None, near=None, far=None; edge_map: preset="paper",
# bounds/near/far=None, normal_filter/depth_filter/ids/inner_threshold/profile_threshold from
# the preset, width=1, k_n=1.0, k_z=1.0; classify_edges: proj=None, model=None,
# crease_angle=30


@functools.cache
def _efb():
    import refraster as rf
    return rf.render([_torus(), _cube()], **_cam(), raster=rf.RasterState(normals="smooth"),
                     model=[np.eye(4), _shift(0.5, -0.2, 0.3) @ np.diag([0.5, 0.5, 0.5, 1.0])])


def case_edge_gbuffer_defaults():
    from refraster import edges
    return _of(edges.edge_gbuffer(_efb()))


def case_edge_gbuffer_bounds():
    from refraster import edges
    return _of(edges.edge_gbuffer(_efb(), bounds=np.array([[-1.5, -1, -1.5], [1.5, 1, 1.5]])))


def case_edge_gbuffer_near_far():
    from refraster import edges
    return _of(edges.edge_gbuffer(_efb(), near=1.5, far=4.5))


def case_edge_map_defaults():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb())}


def case_edge_map_preset_clean():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), preset="clean")}


def case_edge_map_bounds():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), bounds=np.array([[-2, -2, -2], [2, 2, 2]]))}


def case_edge_map_near_far():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), near=1.0, far=6.0)}


def case_edge_map_normal_filter_sobel():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), normal_filter="sobel")}


def case_edge_map_normal_filter_angle():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), normal_filter="angle")}


def case_edge_map_depth_filter_diagonal2():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), depth_filter="diagonal2")}


def case_edge_map_depth_filter_c1():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), depth_filter="c1")}


def case_edge_map_depth_filter_c1_paper():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), depth_filter="c1-paper")}


def case_edge_map_depth_filter_sobel():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), depth_filter="sobel")}


def case_edge_map_ids():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), ids=True)}


def case_edge_map_ids_false_clean():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), preset="clean", ids=False)}


def case_edge_map_inner_threshold():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), inner_threshold=0.05)}


def case_edge_map_profile_threshold():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), profile_threshold=0.02)}


def case_edge_map_width():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), width=3)}


def case_edge_map_k_n():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), normal_filter="sobel", k_n=2.5)}


def case_edge_map_k_z():
    from refraster import edges
    return {"edge_map": edges.edge_map(_efb(), depth_filter="sobel", k_z=3.0)}


def case_edge_map_gbuffer_input():
    from refraster import edges
    gb = edges.edge_gbuffer(_efb(), near=1.5, far=4.5)
    return {"edge_map": edges.edge_map(gb, preset="clean", width=2)}


def case_edge_classify_defaults():
    import refraster as rf
    from refraster import edges
    return _of(edges.classify_edges(_torus(), view=rf.look_at([1.6, 1.2, 2.4], [0, 0, 0])))


def case_edge_classify_options():
    import refraster as rf
    from refraster import edges
    return _of(edges.classify_edges(_torus(), view=rf.look_at([1.6, 1.2, 2.4], [0, 0, 0]),
                                    proj=rf.orthographic(-2, 2, -1.5, 1.5, 0.5, 10),
                                    model=_turn(0.3, [1, 0, 0]), crease_angle=12.0))


def case_edge_classify_perspective_proj():
    import refraster as rf
    from refraster import edges
    return _of(edges.classify_edges(_cube(), view=rf.look_at([1.6, 1.2, 2.4], [0, 0, 0]),
                                    proj=rf.perspective(45, 4 / 3, 0.5, 10),
                                    model=np.diag([-1.0, 1.0, 1.0, 1.0])))


def case_npr_gooch():
    from refraster.edges import npr
    fb = _efb()
    return {"default": npr.gooch(fb.normal),
            "options": npr.gooch(fb.normal, light=(0.3, 0.2, 1.0), base=(0.5, 0.6, 0.7),
                                 cool=(0.0, 0.1, 0.4), warm=(0.4, 0.3, 0.0), alpha=0.3,
                                 beta=0.4, mask=fb.mask, background=(0.9, 0.9, 0.8))}


def case_npr_toon_cartoon():
    from refraster.edges import npr
    fb = _efb()
    t = npr.toon(fb.normal, light=(0.1, 0.5, 1.0), texture=(0.3, 0.6, 0.8, 1.0),
                 color=(0.2, 0.5, 0.9), mask=fb.mask, background=(0, 0, 0))
    return {"toon_default": npr.toon(fb.normal), "toon": t,
            "cartoon": npr.cartoon_map(t, mask=fb.mask), "cartoon_default": npr.cartoon_map(t)}


def case_npr_hatching():
    from refraster.edges import npr
    fb = _efb()
    s = npr.stroke_texture(72, 96, spacing=4.0, angle=30.0, cross_angle=-60.0, first=0.8,
                           cross=0.4)
    return {"strokes_default": npr.stroke_texture(72, 96), "strokes": s,
            "hatch_default": npr.hatching(fb.normal),
            "hatch": npr.hatching(fb.normal, light=(0.2, 0.4, 1.0), strokes=s, softness=0.2,
                                  ambient=0.25, ink=(0.1, 0.0, 0.2), paper=(1.0, 0.95, 0.9),
                                  mask=fb.mask),
            "surface_strokes": npr.surface_strokes(fb, spacing=0.05, angle=20.0)}


def case_npr_composite():
    from refraster import edges
    from refraster.edges import npr
    fb = _efb()
    e = edges.edge_map(fb, preset="clean")
    shade = npr.gooch(fb.normal, mask=fb.mask)
    return {"default": npr.composite(shade, e),
            "options": npr.composite(shade, e, inner_color=(0.5, 0.5, 0.5),
                                     profile_color=(0.2, 0.0, 0.0), mask=fb.mask)}


# ============================================================================== render_samples
# defaults: raster=RasterState(samples=S) with sample_locations="standard",
# interpolation="center"; model=None, background=(1, 1, 1). Every per-sample buffer (colour
# included) and the sample positions.


def _samples(sf):
    out = dict(sf.arrays())
    out["positions"] = sf.positions
    return out


def _rs(**fields):
    import refraster as rf
    return rf.RasterState(**fields)


def _near_cam():
    """The torus seen from inside its near plane's reach: faces cut into clipped pieces."""
    return _cam(eye=(0.0, 0.5, 1.4))


def case_samples_1():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(), raster=_rs(samples=1)))


def case_samples_2_center():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(), raster=_rs(samples=2)))


def case_samples_2_centroid():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=2, interpolation="centroid")))


def case_samples_2_sample():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=2, interpolation="sample")))


def case_samples_4_center():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(), raster=_rs(samples=4)))


def case_samples_4_centroid():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=4, interpolation="centroid")))


def case_samples_4_sample():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=4, interpolation="sample")))


def case_samples_8_center():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(), raster=_rs(samples=8)))


def case_samples_8_centroid():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=8, interpolation="centroid")))


def case_samples_8_sample():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=8, interpolation="sample")))


def case_samples_16_centroid():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=16, interpolation="centroid")))


def case_samples_4_gl_llvmpipe():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=4, sample_locations="gl_llvmpipe")))


def case_samples_4_user_locations():
    """Samples on the pixel's corners and edges (0 and 8 sixteenths): ties with the tie
    scene's edges."""
    import refraster as rf
    return _samples(rf.render_samples(
        _ties(), **_tie_cam(), raster=_rs(samples=4, interpolation="centroid",
                                          sample_locations=[(0, 0), (8, 0), (0, 8), (8, 8)])))


def case_samples_4_ties_top_left():
    import refraster as rf
    return _samples(rf.render_samples(
        _ties(), **_tie_cam(), raster=_rs(samples=4, fill_rule="top-left",
                                          sample_locations=[(0, 0), (8, 0), (0, 8), (8, 8)])))


def case_samples_4_depth_func_greater():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=4, depth_func="greater",
                                                 clear_depth=0.0)))


def case_samples_4_depth_func_lequal():
    import refraster as rf
    return _samples(rf.render_samples(_twice(), **_cam(),
                                      raster=_rs(samples=4, depth_func="lequal",
                                                 interpolation="centroid")))


def case_samples_4_clipped():
    import refraster as rf
    return _samples(rf.render_samples(_torus(), **_near_cam(),
                                      raster=_rs(samples=4, interpolation="centroid")))


def case_samples_8_clipped_sample():
    import refraster as rf
    return _samples(rf.render_samples(_torus(), **_near_cam(),
                                      raster=_rs(samples=8, interpolation="sample")))


def case_samples_4_subpixel_bits_4():
    """Four sub-pixel bits: snapping flips slivers (the snapped edge functions interpolate,
    the depth from the snapped barycentrics)."""
    import refraster as rf
    return _samples(rf.render_samples(_torus(), **_cam(w=48, h=36),
                                      raster=_rs(samples=4, subpixel_bits=4,
                                                 interpolation="sample")))


# ============================================================================== running


def cases():
    """``{name: function}`` in the order of this file."""
    return {k[len("case_"):]: v for k, v in globals().items()
            if k.startswith("case_") and callable(v)}


def run(selected, verbose=False, catch=False):
    """``({name: {output: digest}}, {name: seconds}, {name: error})``; with ``catch``, a case
    that raises is recorded as an error and the others still run."""
    res, times, errors = {}, {}, {}
    for name, fn in selected.items():
        t0 = time.perf_counter()
        try:
            out = fn()
            if not isinstance(out, dict) or not out:
                raise TypeError(f"case {name} must return a non-empty dict")
            res[name] = {k: _digest(v) for k, v in sorted(_of(out).items())}
        except Exception as exc:
            if not catch:
                raise
            errors[name] = f"{type(exc).__name__}: {exc}".splitlines()[0]
        times[name] = time.perf_counter() - t0
        if verbose:
            what = f"({len(res[name])} outputs)" if name in res else f"ERROR {errors[name]}"
            print(f"{times[name]:8.3f} s  {name}  {what}", flush=True)
    return res, times, errors


def _add(ap, path, names, k):
    """``--add FILE NAME…``: run the named cases and add their digests to FILE; refuses a name
    FILE already has (an existing digest is never rewritten) and a name that is no case."""
    if k is not None:
        ap.error("--add takes case names, not -k")
    if not names:
        ap.error("--add FILE needs the NAMEs of the new cases")
    known = cases()
    unknown = [n for n in names if n not in known]
    if unknown:
        ap.error(f"no such case: {', '.join(unknown)}")
    with open(path) as fh:
        ref = json.load(fh)
    present = [n for n in names if n in ref]
    if present:
        ap.error(f"{path} already has {', '.join(present)}: --add never rewrites a digest")
    res, _, _ = run({n: known[n] for n in dict.fromkeys(names)})
    ref.update(res)
    with open(path, "w") as fh:
        json.dump(ref, fh, indent=1, sort_keys=True)
        fh.write("\n")
    print(f"{len(res)} cases added to {path} ({len(ref)} cases)")
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", metavar="FILE", help="record every case (a new file)")
    g.add_argument("--check", metavar="FILE", help="compare with FILE (exit 1 on a difference)")
    g.add_argument("--add", metavar="FILE",
                   help="record only the NAMEd cases into FILE, which must not have them yet")
    g.add_argument("--list", action="store_true", help="the cases' names")
    ap.add_argument("names", nargs="*", metavar="NAME", help="with --add: the new cases")
    ap.add_argument("-k", metavar="SUBSTRING", help="only the cases whose name contains it")
    ap.add_argument("-v", "--verbose", action="store_true", help="per-case times")
    a = ap.parse_args(argv)
    if a.add is not None:
        return _add(ap, a.add, a.names, a.k)
    if a.names:
        ap.error("case names are only taken by --add")
    selected = {k: v for k, v in cases().items() if a.k is None or a.k in k}
    if a.list and not a.verbose:
        for name in selected:
            print(name)
        return 0
    t0 = time.perf_counter()
    res, _, errors = run(selected, a.verbose, catch=bool(a.check or a.list))
    total = time.perf_counter() - t0
    n_out = sum(len(v) for v in res.values())
    if a.list:
        print(f"{len(res)} cases, {n_out} outputs, {total:.1f} s"
              + (f", {len(errors)} raised" if errors else ""))
        return 1 if errors else 0
    if a.write:
        if a.k is not None:
            ap.error("--write records every case; drop -k")
        with open(a.write, "w") as fh:
            json.dump(res, fh, indent=1, sort_keys=True)
            fh.write("\n")
        print(f"{len(res)} cases, {n_out} outputs -> {a.write} ({total:.1f} s)")
        return 0
    with open(a.check) as fh:
        ref = json.load(fh)
    if a.k is not None:
        ref = {k: v for k, v in ref.items() if a.k in k}
    bad = []
    for name in sorted(set(ref) | set(res) | set(errors)):
        if name in errors:
            bad.append(name)
            print(f"ERROR: {name}: {errors[name]}")
        elif name not in res and name not in selected:
            bad.append(name)
            print(f"MISSING: {name}: in {a.check}, no such case")
        elif name not in ref:
            bad.append(name)
            print(f"NEW: {name}: not in {a.check}")
        else:
            outs = [o for o in sorted(set(ref[name]) | set(res[name]))
                    if ref[name].get(o) != res[name].get(o)]
            if outs:
                bad.append(name)
                print(f"DIFFERS: {name}: {', '.join(outs)}")
    print(f"{len(selected)} cases checked ({total:.1f} s): "
          f"{'all equal' if not bad else f'{len(bad)} differ, raised or are missing'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
