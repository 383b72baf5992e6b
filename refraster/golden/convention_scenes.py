"""Golden scenes in the other APIs' conventions (issue 39): the plain scenes as Vulkan draws
them, reversed-Z with an infinite far plane, a depth peel under reversed-Z, geometry crossing
z = 0 and the eye plane (with and without depth clamp), Direct3D's exact ties, and fixed-point
depth buffers. Each is a plain-rendering scene (``technique="render"``) but the peel
(``"ldi"``); the raster fields are stored in ``scene.json`` and the allowances follow them
(:mod:`refraster.golden.allowances.conventions`, ``docs/tolerance.md``, "Conventions")."""

from __future__ import annotations

import math

import numpy as np

from ..camera import Camera, look_at, orthographic, perspective
from .conventions import API_CONVENTIONS, in_convention
from .scenes import (SCENES, Draw, GoldenScene, _framed, _translate, _rotate_x, prepare_draws,
                     raster_state, register_scene, render_scene)

__all__ = ["REVERSED_Z", "VULKAN_SCENES"]

#: Reversed-Z as engines use it: clip depth [0, 1], near → 1, infinity → 0, float32,
#: ``greater``, cleared to 0 (with ``camera.perspective(..., reversed=True, far=math.inf,
#: depth_range="zero_to_one")``).
REVERSED_Z = dict(depth_range="zero_to_one", depth_func="greater", clear_depth=0.0)
#: Plain scenes re-rendered in Vulkan's conventions (``vulkan_<scene>``).
VULKAN_SCENES = ("render_cube", "render_icosphere_smooth", "render_torus_ortho",
                 "render_nested_shells", "render_multi_draw")


def _register_vulkan(name):
    entry = SCENES[name]
    short = name.removeprefix("render_")

    @register_scene(f"vulkan_{short}", technique="render",
                    description=f"{entry.description} In Vulkan's conventions: clip depth [0, 1], "
                                "upper-left origin, NDC y down (the picture mirrored top to "
                                "bottom), front face cw (the same faces front).")
    def build(**params):   # sizes and raster sweeps pass through to the plain scene
        return in_convention(entry, "vulkan").build(**params)

    return build


for _name in VULKAN_SCENES:
    _register_vulkan(_name)


def _multi_draw_draws():
    from ..scenes import solid
    return [Draw("cube", solid("cube"), _translate(-0.6, 0.0, 0.0)),
            Draw("torus", solid("torus", quick=True), _translate(0.2, 0.0, 0.0) @ _rotate_x(70)),
            Draw("icosphere", solid("icosphere", quick=True), _translate(1.5, 0.3, -0.4))]


@register_scene("reversed_z_multi_draw", technique="render",
                description="The three draws of render_multi_draw under reversed-Z: an infinite "
                            "far plane, clip depth [0, 1] (near at 1), float32, greater, "
                            "cleared to 0; WebGPU's window conventions, back faces culled.")
def _reversed_z_multi_draw(width=160, height=120):
    view = look_at((1.0, 2.5, 5.0), (0.4, 0.0, 0.0))
    proj = perspective(35.0, width / height, 2.0, math.inf, reversed=True,
                       depth_range="zero_to_one")
    return render_scene(_multi_draw_draws(), Camera(view, proj, width, height),
                        raster={**REVERSED_Z, **_window("webgpu"), "cull": "back"})


def _window(api):
    return {k: v for k, v in API_CONVENTIONS[api].items() if k != "depth_range"}


@register_scene("reversed_z_peel", technique="ldi",
                description="Depth peeling of the nested shells under reversed-Z (infinite far "
                            "plane, greater, cleared to 0): layer 0 the nearest, depths "
                            "decreasing from layer to layer.")
def _reversed_z_peel():
    from ..ldi import peel
    from ..scenes import solid
    from .scenes import as_state
    raster = {**REVERSED_Z, **_window("vulkan"), "front_face": "cw"}
    state = raster_state(raster)
    draws = prepare_draws([Draw("nested_shells", solid("nested_shells", quick=True))])
    framed = _framed([d.mesh for d in draws], 128, 96, (1.2, 0.9, 1.6))
    near, _ = framed.near_far
    proj = perspective(35.0, 128 / 96, near, math.inf, reversed=True, depth_range="zero_to_one")
    camera = Camera(framed.view, proj, 128, 96)
    params = dict(mode="peel", max_layers=None)
    layers = peel([d.mesh for d in draws], **camera.kwargs, model=[d.model for d in draws],
                  raster=as_state(state), **params)
    buffers = {
        "layer_depth": np.ascontiguousarray(np.moveaxis(layers.depth, 0, -1)),
        "layer_prim_id": np.ascontiguousarray(np.moveaxis(layers.prim_id, 0, -1)),
        "layer_front_facing": np.ascontiguousarray(np.moveaxis(layers.front_facing, 0, -1)),
        "layer_count": np.asarray(layers.count, np.int32),
    }
    faces = sum(len(d.mesh.faces) for d in draws)
    return GoldenScene(technique="ldi", camera=camera, draws=draws, buffers=buffers,
                       parameters=params, raster=raster, kinds={"layer_depth": "unorm"},
                       geometry=False, ids={"layer_count": (0, faces)})


def _ground(half=40.0, y=0.0):
    v = np.array([[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]])
    return v, np.array([[0, 2, 1], [0, 3, 2]])


def _crossing(width, height, raster):
    """A ground plane that passes under and behind the eye, a torus cut by the near plane."""
    from ..scenes import solid
    draws = [Draw("ground", _ground(), np.eye(4)),
             Draw("torus", solid("torus", quick=True), _translate(0.0, 0.5, 1.6) @ _rotate_x(80))]
    view = look_at((0.0, 1.2, 3.0), (0.0, 0.3, 0.0))
    proj = perspective(50.0, width / height, 1.4, 30.0, depth_range="zero_to_one")
    return render_scene(draws, Camera(view, proj, width, height), raster=raster)


@register_scene("zero_to_one_near_crossing", technique="render",
                description="Clip depth [0, 1]: a torus cut by the near plane (clipping at "
                            "z = 0) and a ground plane reaching behind the eye; Direct3D's "
                            "window conventions.")
def _zero_to_one_near_crossing(width=160, height=120):
    return _crossing(width, height, {**_window("d3d12"), "depth_range": "zero_to_one"})


@register_scene("depth_clamp_near_crossing", technique="render",
                description="zero_to_one_near_crossing with depth clamp: nothing clipped at the "
                            "near or far plane, depth clamped to [0, 1]; the ground plane still "
                            "clipped at the eye plane (w > 0).")
def _depth_clamp_near_crossing(width=160, height=120):
    return _crossing(width, height, {**_window("d3d12"), "depth_range": "zero_to_one",
                                     "depth_clamp": True})


def _tie_grid(n_x, n_y, step):
    """A grid of quads (two triangles each, alternate diagonals) whose vertices lie on pixel
    centres ``(step·i + ½, step·j + ½)`` in window pixels, z rising with x: every edge —
    horizontal, vertical, diagonal — passes exactly through pixel centres."""
    xs = step * np.arange(n_x + 1) + 0.5
    ys = step * np.arange(n_y + 1) + 0.5
    gx, gy = np.meshgrid(xs, ys)
    v = np.column_stack([gx.ravel(), gy.ravel(), -1.0 - 0.01 * gx.ravel() - 0.005 * gy.ravel()])
    faces = []
    for j in range(n_y):
        for i in range(n_x):
            a = j * (n_x + 1) + i
            b, c, d = a + 1, a + n_x + 2, a + n_x + 1
            faces += ([[a, b, c], [a, c, d]] if (i + j) % 2 == 0 else [[a, b, d], [b, c, d]])
    return v, np.array(faces)


@register_scene("d3d12_exact_ties", technique="render",
                description="Direct3D 12's conventions (clip depth [0, 1], upper-left origin, "
                            "top-left fill rule): a grid whose every edge passes exactly "
                            "through pixel centres, orthographic, one window pixel per unit "
                            "(2/64: every coordinate exact in float32).")
def _d3d12_exact_ties(width=64, height=64):
    step = 6
    v, f = _tie_grid((width - 4) // step, (height - 4) // step, step)
    view = np.eye(4)
    proj = orthographic(0.0, float(width), 0.0, float(height), 0.5, 4.0,
                        depth_range="zero_to_one")
    raster = {**API_CONVENTIONS["d3d12"], "cull": "back"}
    return render_scene([Draw("grid", (v, f))], Camera(view, proj, width, height),
                        raster=raster)


@register_scene("unorm24_torus_ortho", technique="render",
                description="render_torus_ortho into a 24-bit fixed-point depth buffer "
                            "(GL_DEPTH_COMPONENT24): the allowance adds 0.6 of a step.")
def _unorm24_torus_ortho(width=160, height=120):
    entry = SCENES["render_torus_ortho"]
    return entry.build(width=width, height=height, depth_format="unorm24")


@register_scene("unorm16_planes", technique="render",
                description="Three overlapping quads facing the camera (constant window depth "
                            "each) in WebGPU's conventions into depth16unorm: the allowance is "
                            "the relative float model plus 0.6 of a 16-bit step, so a depth off "
                            "by two steps is outside it.")
def _unorm16_planes(width=96, height=72):
    quad = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    draws = [Draw(f"quad{k}", (quad, faces), _translate(0.6 * k - 0.6, 0.3 * k - 0.3, -1.5 * k))
             for k in range(3)]
    view = look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0))
    proj = perspective(40.0, width / height, 2.0, 12.0, depth_range="zero_to_one")
    raster = {**_window("webgpu"), "depth_range": "zero_to_one", "depth_format": "unorm16"}
    return render_scene(draws, Camera(view, proj, width, height), raster=raster)
