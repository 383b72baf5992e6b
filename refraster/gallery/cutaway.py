"""Gallery: adaptive cutaways (Burns & Finkelstein 2008) on procedural stand-ins of the paper's
scenes: nested shells, a house with radiators (Fig. 6, 8), a hull with cannons (Fig. 1), an
office block with an invisible stand-in (Fig. 9), and a camera pan (Fig. 7)."""

from __future__ import annotations

import pathlib

import numpy as np

from .. import look_at, perspective
from ..cutaway import render_cutaway
from ..io import write_png
from ..scenes import building, cube, icosphere, nested_shells
from . import Item

SECTION = "Adaptive cutaways"


def _box(lo, hi):
    c = cube(1.0)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return (np.asarray(c.vertices) + 0.5) * (hi - lo) + lo, np.asarray(c.faces)


def _cylinder(centre, radius, length, axis=0, segments=16):
    import trimesh
    m = trimesh.creation.cylinder(radius=radius, height=length, sections=segments)
    rot = {0: trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]),
           1: trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]), 2: np.eye(4)}[axis]
    m.apply_transform(rot)
    m.apply_translation(centre)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _scaled(mesh, scale, offset=(0, 0, 0)):
    return np.asarray(mesh.vertices) * scale + offset, np.asarray(mesh.faces)


def _camera(eye, target, w, h, fovy=40.0, near=0.5, far=60.0):
    return dict(view=look_at(eye, target), proj=perspective(fovy, w / h, near, far),
                width=w, height=h)


def _panels(images):
    gap = np.ones((images[0].shape[0], 4, 3), np.float32)
    out = [images[0]]
    for im in images[1:]:
        out += [gap, im]
    return np.concatenate(out, axis=1)


def _shells(out, s):
    shells = nested_shells((1.2, 1.05, 0.8, 0.68), subdivisions=3)
    core = [icosphere(3, radius=0.3), _box((0.2, -0.1, 0.2), (0.5, 0.2, 0.5))]
    cam = _camera((2.6, 1.6, 3.0), (0, 0, 0), s, s)
    imgs = [render_cutaway(core, shells, **cam, angle=a, ghost_distance=0.6).image
            for a in (0.35, 0.7)]
    write_png(out / "cutaway_shells.png", _panels(imgs))
    return Item(SECTION, "cutaway_shells.png",
                "Nested shells cut away to expose a sphere and a box inside (θ = 0.35 and 0.7 "
                "rad): cut surfaces shaded with the cutaway's normals and outlined, ghost lines "
                "fading in front of the cut.")


def _house():
    parts = [_box((-5, -0.2, -4), (5, 0, 4))]                       # floor slab
    parts += [_box((-5, 0, -4), (5, 2.5, -3.8)), _box((-5, 0, 3.8), (5, 2.5, 4)),
              _box((-5, 0, -3.8), (-4.8, 2.5, 3.8)), _box((4.8, 0, -3.8), (5, 2.5, 3.8)),
              _box((-0.1, 0, -3.8), (0.1, 2.5, 1.0))]                # walls
    radiators = [_box((-3.5, 0.2, -3.7), (-2.3, 0.9, -3.5)),
                 _box((1.0, 0.2, -3.7), (2.4, 0.9, -3.5)),
                 _box((4.5, 0.2, 0.5), (4.7, 0.9, 1.7))]
    return parts, radiators


def _radiators(out, s):
    parts, radiators = _house()
    cam = _camera((-1.0, 7.5, 11.0), (0, 0.5, -1.0), s, s)
    wide = render_cutaway(radiators, parts, **cam, angle=0.9, ghost_distance=1.0).image
    local = render_cutaway(radiators, parts, **cam, angle=[0.35, 0.9, 0.5],
                           ghost_distance=1.0).image
    write_png(out / "cutaway_radiators.png", _panels([wide, local]))
    items = [Item(SECTION, "cutaway_radiators.png",
                  "Three radiators in a house (Fig. 6): one wide angle for all (left) and a "
                  "different angle per radiator, 0.35 / 0.9 / 0.5 rad (right, Sec. 5.3).")]
    cam = _camera((0.0, 3.2, 9.0), (0, 0.4, -2.0), s, s)
    plain = render_cutaway(radiators, parts, **cam, angle=0.9).image
    floor = render_cutaway(radiators, parts, **cam, angle=0.9, floor_normal=(0, 1, 0)).image
    write_png(out / "cutaway_floor.png", _panels([plain, floor]))
    items.append(Item(SECTION, "cutaway_floor.png",
                      "Directional constraint (Fig. 8): without it the floor in front of the "
                      "radiators is carved (left); with the floor normal (0, 1, 0) the cutaway "
                      "avoids the floor (right; MATH.md D-C7)."))
    return items


def _galleon(out, s, quick):
    hull = _scaled(nested_shells((1.0, 0.93), subdivisions=2 if quick else 3), (4.0, 1.0, 1.2))
    cannons = [_cylinder((x, y, z), 0.09, 0.7, axis=2)
               for x in np.linspace(-2.4, 2.4, 4 if quick else 6)
               for y, z in ((-0.25, 0.45), (0.3, 0.4))]
    frames = []
    for eye in ((3.0, 2.0, 6.0), (-2.0, 1.2, 6.0), (0.5, 0.6, 3.5)):
        cam = _camera(eye, (0, 0, 0), s, (3 * s) // 4)
        frames.append(render_cutaway(cannons, hull, **cam, angle=0.45,
                                     ghost_distance=0.5).image)
    write_png(out / "cutaway_galleon.png", _panels(frames))
    return Item(SECTION, "cutaway_galleon.png",
                "A hull cut away to reveal rows of cannons (Fig. 1), from three cameras; the "
                "cutaway follows the view.")


def _office(out, s):
    house = building()
    room = _box((0.5, 0.3, 0.5), (5.6, 2.9, 6.5))       # invisible stand-in for room A
    furniture = [_box((1.5, 0.25, 2.0), (3.5, 1.0, 3.2)),
                 _box((4.0, 0.25, 4.5), (4.8, 1.6, 5.2))]
    cam = _camera((16.0, 11.0, 17.0), (5.0, 2.0, 3.5), s, s)
    a = render_cutaway(furniture, house, **cam, stand_ins=[room], angle=[0.3, 0.3, 0.3],
                       ghost_distance=1.5)
    b = render_cutaway(furniture, house, **cam, stand_ins=[room], angle=0.6,
                       ghost_distance=1.5)
    write_png(out / "cutaway_office.png", _panels([a.image, b.image]))
    return Item(SECTION, "cutaway_office.png",
                "An office block with an invisible stand-in box for a room (Fig. 9): the box "
                "shapes the cutaway but is never drawn; the furniture is the object of "
                "interest. θ = 0.3 rad (left) and 0.6 rad (right).")


def _pan(out, s):
    wall = [_box((-6, 0, 0), (6, 3, 0.3)), _box((-6, -0.2, -3), (6, 0, 3))]
    target = [_box((-0.4, 0, -1.5), (0.4, 1.2, -0.7))]
    w, h = s, (2 * s) // 3
    rows = []
    for compression in (None, 0.1):
        frames = []
        for x in (-1.5, -3.3, -4.3):       # the camera pans left; the box exits on the right
            cam = _camera((x, 2.5, 6.0), (x, 1.0, 0.0), w, h)
            frames.append(render_cutaway(target, wall, **cam, angle=0.6,
                                         edge_compression=compression).image)
        rows.append(_panels(frames))
    sep = np.ones((4, rows[0].shape[1], 3), np.float32)
    write_png(out / "cutaway_pan.png", np.concatenate([rows[0], sep, rows[1]], axis=0))
    return Item(SECTION, "cutaway_pan.png",
                "Camera pan (Fig. 7): the object of interest leaves the frame. Top: without "
                "edge compression the cut stays wide until the object is gone and then pops; "
                "bottom: with r = 0.1 it narrows toward the border (Sec. 5.4).")


def render(out_dir: pathlib.Path, *, quick: bool = False) -> list[Item]:
    """Render the cutaway gallery pictures into ``out_dir``; ``quick`` uses small images."""
    out = pathlib.Path(out_dir)
    s = 96 if quick else 360
    items = [_shells(out, s)]
    items += _radiators(out, s)
    items.append(_galleon(out, s, quick))
    items.append(_office(out, s))
    items.append(_pan(out, s))
    return items
