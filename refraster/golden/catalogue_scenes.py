"""Golden scenes of the catalogue of GPU bug classes (issue 41, ``docs/conformance.md``): each
is there for classes of implementation bug no other built-in scene catches — non-uniform and
mirrored model matrices, huge triangles past any guard band, a plane crossing the near plane
and passing behind the eye, a depth-precision stress (near/far 1e-3/1e4), more than 65,535
vertices in one draw, shared edges through exact pixel centres with zero-area triangles ahead of
them in the index buffer. All are plain-rendering scenes in OpenGL's conventions."""

from __future__ import annotations

import numpy as np

from ..camera import Camera, look_at, orthographic, perspective
from .scenes import Draw, _rotate_x, _translate, register_scene, render_scene

__all__ = ["MANY_VERTICES"]

#: Vertices of catalogue_many_vertices' single draw (more than a 16-bit index can address).
MANY_VERTICES = 258 * 255


def _scale(x, y, z):
    return np.diag([float(x), float(y), float(z), 1.0])


def _rotate_y(degrees):
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    m = np.eye(4)
    m[0, 0], m[0, 2], m[2, 0], m[2, 2] = c, s, -s, c
    return m


@register_scene("catalogue_transforms", technique="render",
                description="Non-uniform and mirrored model matrices: an icosphere scaled "
                            "(1.8, 0.6, 1) (normals need the inverse transpose) and a cube "
                            "mirrored in x (negative determinant: its outward faces wind "
                            "clockwise in the window, so they are back faces).")
def _catalogue_transforms(width=96, height=72):
    from ..scenes import solid
    draws = [Draw("ellipsoid", solid("icosphere", quick=True),
                  _translate(-0.9, 0.0, 0.0) @ _rotate_y(30) @ _scale(1.8, 0.6, 1.0)),
             Draw("mirrored_cube", solid("cube"),
                  _translate(1.1, 0.0, 0.0) @ _rotate_y(25) @ _scale(-1.0, 1.0, 1.0))]
    view = look_at((0.5, 2.0, 5.5), (0.2, 0.0, 0.0))
    camera = Camera(view, perspective(35.0, width / height, 2.0, 10.0), width, height)
    return render_scene(draws, camera)


def _eye_point(proj, ndc_x, ndc_y, eye_z):
    """The eye-space point at depth ``eye_z`` (< 0) that ``proj`` maps to ``(ndc_x, ndc_y)``."""
    w = -eye_z
    return [ndc_x * w / proj[0, 0], ndc_y * w / proj[1, 1], eye_z]


@register_scene("catalogue_huge_near", technique="render",
                description="Huge triangles and the near plane: a wall triangle whose vertices "
                            "lie a thousand viewports away (one edge crosses the picture with "
                            "slope 0.1) and a ground plane that crosses the near plane and "
                            "passes under and behind the eye (w -> 0 and w < 0 at its "
                            "vertices), a small box cut by the near plane.")
def _catalogue_huge_near(width=96, height=72):
    from ..scenes import solid
    proj = perspective(50.0, width / height, 0.5, 60.0)
    a = 1000.0
    wall = np.array([_eye_point(proj, -a, 0.3 - 0.1 * a, -8.0),
                     _eye_point(proj, a, 0.3 + 0.1 * a, -8.0),
                     _eye_point(proj, -a, a, -8.0)])
    ground = np.array([[-50.0, -1.0, 50.0], [50.0, -1.0, 50.0], [50.0, -1.0, -50.0],
                       [-50.0, -1.0, -50.0]])
    draws = [Draw("wall", (wall, np.array([[0, 1, 2]]))),
             Draw("ground", (ground, np.array([[0, 1, 2], [0, 2, 3]]))),
             Draw("near_box", solid("cube"), _translate(0.3, -0.15, -0.5) @ _rotate_y(35)
                  @ _scale(0.08, 0.08, 0.08))]
    return render_scene(draws, Camera(np.eye(4), proj, width, height))


@register_scene("catalogue_depth_precision", technique="render",
                description="Depth-precision stress in clip depth [0, 1] (the relative float "
                            "depth model): near/far 1e-3/1e4, cubes from 2 to 40 "
                            "eye units away and a pair of overlapping quads 0.5 apart at 6 "
                            "(window depths within 1e-3 of 1: float32 keeps them apart, a "
                            "16-bit depth buffer does not keep their values).")
def _catalogue_depth_precision(width=96, height=72):
    from ..scenes import solid
    quad = (np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]),
            np.array([[0, 1, 2], [0, 2, 3]]))
    draws = [Draw("near_cube", solid("cube"), _translate(-1.0, -0.4, -2.0) @ _rotate_y(30)
                  @ _scale(0.4, 0.4, 0.4)),
             Draw("far_cube", solid("cube"), _translate(9.0, 4.0, -40.0) @ _rotate_y(20)
                  @ _scale(3.0, 3.0, 3.0)),
             Draw("quad_a", quad, _translate(0.6, 0.0, -6.0)),
             Draw("quad_b", quad, _translate(1.1, 0.5, -6.5) @ _rotate_y(10))]
    proj = perspective(45.0, width / height, 1e-3, 1e4, depth_range="zero_to_one")
    return render_scene(draws, Camera(np.eye(4), proj, width, height),
                        raster={"depth_range": "zero_to_one"})


@register_scene("catalogue_many_vertices", technique="render",
                description="One draw of 65,790 vertices (258 x 255, past what a 16-bit index "
                            "addresses): a rippled height field seen from above.")
def _catalogue_many_vertices(width=96, height=72):
    nx, ny = 258, 255
    xs, ys = np.linspace(-1.5, 1.5, nx), np.linspace(-1.0, 1.0, ny)
    gx, gy = np.meshgrid(xs, ys)
    gz = 0.08 * np.sin(5.0 * gx) * np.cos(4.0 * gy)
    v = np.column_stack([gx.ravel(), gz.ravel(), gy.ravel()])
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    faces = np.concatenate([np.column_stack([a, a + nx, a + 1]),
                            np.column_stack([a + 1, a + nx, a + nx + 1])])
    view = look_at((0.0, 3.2, 1.6), (0.0, 0.0, 0.0))
    camera = Camera(view, perspective(40.0, width / height, 1.0, 8.0), width, height)
    return render_scene([Draw("field", (v, faces))], camera)


@register_scene("catalogue_pixel_centres", technique="render",
                description="Shared edges through exact pixel centres in OpenGL's conventions: "
                            "a grid whose every edge passes through pixel centres (either fill "
                            "rule must cover each such centre once), orthographic, one window "
                            "pixel per unit, with two zero-area triangles (collinear, off "
                            "screen) first in the index buffer.")
def _catalogue_pixel_centres(width=64, height=64):
    from .convention_scenes import _tie_grid
    step = 6
    v, f = _tie_grid((width - 4) // step, (height - 4) // step, step)
    extra = np.array([[-20.0, -20.0, -1.0], [-15.0, -20.0, -1.0], [-10.0, -20.0, -1.0]])
    n = len(v)
    faces = np.concatenate([[[n, n + 1, n + 2], [n, n, n + 1]], f])
    proj = orthographic(0.0, float(width), 0.0, float(height), 0.5, 4.0)
    return render_scene([Draw("grid", (np.concatenate([v, extra]), faces))],
                        Camera(np.eye(4), proj, width, height))
