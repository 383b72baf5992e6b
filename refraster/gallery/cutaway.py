"""Gallery: adaptive cutaways (Burns & Finkelstein 2008) on procedural stand-ins of the paper's
scenes: nested shells, the rendering effects of Fig. 4 (a–e) on nested box shells, perspective
compensation (Fig. 5), a house with radiators (Fig. 6, 8), a hull with cannons (Fig. 1), an
office block with an invisible stand-in (Fig. 9), a camera pan (Fig. 7) and two objects of
interest shaping one surface (Fig. 10)."""

from __future__ import annotations

import pathlib

import numpy as np

from .. import look_at, perspective
from ..cutaway import (CutSurfaces, Cutaway, GhostLines, chamfer, cutaway_surface, exact,
                       jump_flood, render_cutaway)
from ..cutaway.surface import ndc_to_eye_depth, pixel_ndc, seed_slopes, tangent_sampling, unproject
from ..framebuffer import render as _render
from ..raster.state import RasterState
from ..camera import orthographic
from ..io import write_png
from ..scenes import building, cube, icosphere, nested_shells
from . import Item

#: The rear hull of the objects of interest: their farthest surface (Burns & Finkelstein
#: Sec. 4.1), depth test greater over a buffer cleared to 0.
REAR_HULL = RasterState(depth_func="greater", clear_depth=0.0)

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
    imgs = [render_cutaway(core, shells, **cam, cutaway=Cutaway(angle=a),
                           ghosts=GhostLines(distance=0.6)).image
            for a in (0.35, 0.7)]
    write_png(out / "cutaway_shells.png", _panels(imgs))
    return Item(SECTION, "cutaway_shells.png",
                "Nested shells cut away to expose a sphere and a box inside (θ = 0.35 and 0.7 "
                "rad): cut surfaces shaded with the cutaway's normals and outlined. The removed "
                "caps of smooth spheres have no creases and their silhouettes are not removed, "
                "so there are no ghost lines here (see the box shells of Fig. 4).")


def _house():
    parts = [_box((-5, -0.2, -4), (5, 0, 4))]                       # floor slab
    parts += [_box((-5, 0, -4), (5, 2.5, -3.8)), _box((-5, 0, 3.8), (5, 2.5, 4)),
              _box((-5, 0, -3.8), (-4.8, 2.5, 3.8)), _box((4.8, 0, -3.8), (5, 2.5, 3.8)),
              _box((-0.1, 0, -3.8), (0.1, 2.5, 1.0))]                # walls
    radiators = [_box((-3.5, 0.2, -3.7), (-2.3, 0.9, -3.5)),
                 _box((1.0, 0.2, -3.7), (2.4, 0.9, -3.5)),
                 _box((4.5, 0.2, 0.5), (4.7, 0.9, 1.7))]
    return parts, radiators


def box_shell(a, b):
    """A hollow cube: the outer box [−a, a]³ facing out, the inner [−b, b]³ facing in."""
    v1, f1 = _box((-a,) * 3, (a,) * 3)
    v2, f2 = _box((-b,) * 3, (b,) * 3)
    return np.concatenate([v1, v2]), np.concatenate([f1, f2[:, ::-1] + len(v1)])


def _fig4(out, s):
    shells = [box_shell(1.2, 1.05), box_shell(0.8, 0.68)]
    core = [icosphere(3, radius=0.3)]
    cam = _camera((2.8, 2.2, 3.4), (0, 0, 0), s, s)
    cut = Cutaway(angle=0.5)
    panels = [
        render_cutaway(core, shells, **cam, cutaway=cut, ghosts=None,
                       cut_surfaces=CutSurfaces(shade=False, outlines=False)),
        render_cutaway(core, shells, **cam, cutaway=cut, ghosts=None,
                       cut_surfaces=CutSurfaces(outlines=False)),
        render_cutaway(core, shells, **cam, cutaway=cut, ghosts=None),
        render_cutaway(core, shells, **cam, cutaway=cut,
                       ghosts=GhostLines(distance=100.0, fade=False)),
        render_cutaway(core, shells, **cam, cutaway=cut, ghosts=GhostLines(distance=1.0)),
    ]
    write_png(out / "cutaway_fig4.png", _panels([p.image for p in panels]))
    return Item(SECTION, "cutaway_fig4.png",
                "Rendering effects (Fig. 4) on two nested box shells around a sphere, θ = 0.5: "
                "(a) clipping alone leaves the walls hollow; (b) cut surfaces shaded with the "
                "cutaway's normals; (c) outlined; (d) ghost lines: every removed crease and "
                "silhouette of both shells, unfaded and unlimited; (e) faded, drawn up to "
                "g_max = 1 in front of the cut with α = 1 − (D − z)/g_max in eye depth.")


#: Fig. 5: fields of view (zoomed out, middle, zoomed in) and the angles of the two rows; the
#: uncompensated angle (a cone in NDC) is chosen so that both carve the same share of the crate at
#: the middle zoom (measured: 0.37 and 0.36 of its pixels).
FIG5_FOVS = (75.0, 40.0, 20.0)
FIG5_ANGLES = ((False, 1.5), (True, 0.45))


def _fig5(out, s):
    shell = [box_shell(1.0, 0.85)]
    core = [icosphere(3, radius=0.35)]
    rows = []
    for comp, theta in FIG5_ANGLES:
        frames = []
        for fov in FIG5_FOVS:
            cam = _camera((3.3, 2.7, 4.2), (0, 0, 0), s, s, fovy=fov, near=0.3, far=40.0)
            frames.append(render_cutaway(core, shell, **cam, ghosts=None, cutaway=Cutaway(
                angle=theta, perspective_compensation=comp, edge_compression=None)).image)
        rows.append(_panels(frames))
    sep = np.ones((4, rows[0].shape[1], 3), np.float32)
    write_png(out / "cutaway_fig5.png", np.concatenate([rows[0], sep, rows[1]], axis=0))
    return Item(SECTION, "cutaway_fig5.png",
                "Perspective compensation (Fig. 5): a hollow crate zoomed out, middle and zoomed "
                "in (field of view 75°, 40°, 20°). Top: the basic surface (a cone in NDC, "
                "θ = 1.5 chosen to match the bottom row at the middle zoom) is too wide zoomed "
                "out and too narrow zoomed in. Bottom: with Eq. 3 (corrected, MATH.md D-C4) "
                "θ = 0.45 keeps its shape at every zoom.")


def radiator_house():
    """Fig. 6's house: a floor, a back wall with a radiator at each side and, in front, a
    partition wall carrying the third radiator on its near face (radiators touch their walls).

    Returns ``(secondary boxes, radiators, camera kwargs for size 1)``: the boxes as
    ``(vertices, faces)`` of axis-aligned boxes."""
    parts = [_box((-5, -0.2, -2.4), (5, 0, 3.0)),                  # floor slab
             _box((-5, 0, -2.4), (5, 2.5, -2.2)),                  # back wall
             _box((-3.6, 0, -0.2), (3.6, 2.5, 0.0))]               # partition wall
    radiators = [_box((-2.6, 0.3, -2.2), (-1.4, 1.0, -2.0)),       # back wall, left
                 _box((-0.5, 0.3, 0.0), (0.5, 1.0, 0.2)),          # partition, centre
                 _box((1.4, 0.3, -2.2), (2.6, 1.0, -2.0))]         # back wall, right
    return parts, radiators, dict(eye=(1.5, 5.0, 7.0), target=(0.0, 0.6, -1.0))


#: Fig. 6's angles: one wide global angle, and one per radiator.
RADIATOR_ANGLES = (0.7, [0.25, 0.5, 0.25])


def _radiators(out, s):
    parts, radiators, view = radiator_house()
    cam = _camera(view["eye"], view["target"], s, s)
    wide, local = (render_cutaway(radiators, parts, **cam, cutaway=Cutaway(angle=a),
                                  ghosts=GhostLines(distance=1.0)).image
                   for a in RADIATOR_ANGLES)
    write_png(out / "cutaway_radiators.png", _panels([wide, local]))
    items = [Item(SECTION, "cutaway_radiators.png",
                  "Local angles (Fig. 6): three radiators, two on the back wall hidden by a "
                  "partition and one on the partition. Left: one wide angle (0.7 rad) for all "
                  "carves the partition away behind the centre radiator, which floats. Right: "
                  "0.25 / 0.5 / 0.25 rad per radiator (Sec. 5.3) keeps the partition around it.")]
    parts, radiators = _house()
    cam = _camera((0.0, 3.2, 9.0), (0, 0.4, -2.0), s, s)
    plain = render_cutaway(radiators, parts, **cam, cutaway=Cutaway(angle=0.9)).image
    floor = render_cutaway(radiators, parts, **cam,
                           cutaway=Cutaway(angle=0.9, floor_normal=(0, 1, 0))).image
    write_png(out / "cutaway_floor.png", _panels([plain, floor]))
    items.append(Item(SECTION, "cutaway_floor.png",
                      "Directional constraint (Fig. 8): without it the floor in front of the "
                      "radiators is carved (left); with the floor normal (0, 1, 0) the cutaway "
                      "avoids the floor (right; MATH.md D-C7)."))
    return items


#: The galleon's three cameras (eye positions, looking at the origin).
GALLEON_EYES = ((3.0, 2.0, 6.0), (-2.0, 1.2, 6.0), (0.5, 0.6, 3.5))


def galleon_frames(s, quick, *, deck=True):
    """The galleon's three cutaway framebuffers (``s`` × 3s/4 each): the cannons as objects of
    interest; the hull and, with ``deck``, the gun deck as secondary objects."""
    hull = _scaled(nested_shells((1.0, 0.93), subdivisions=2 if quick else 3), (4.0, 1.0, 1.2))
    cannons = [_cylinder((x, y, z), 0.09, 0.7, axis=2)
               for x in np.linspace(-2.4, 2.4, 4 if quick else 6)
               for y, z in ((-0.25, 0.45), (0.3, 0.4))]
    # the gun deck under the upper row, inside the inner hull: its box edges are creases, so
    # its removed front edge comes back as ghost lines (the smooth hull has none to give)
    secondary = [hull, _box((-2.65, 0.16, -0.7), (2.65, 0.21, 0.7))] if deck else [hull]
    return [render_cutaway(cannons, secondary, **_camera(eye, (0, 0, 0), s, (3 * s) // 4),
                           cutaway=Cutaway(angle=0.45), ghosts=GhostLines(distance=1.0))
            for eye in GALLEON_EYES]


def _galleon(out, s, quick):
    write_png(out / "cutaway_galleon.png", _panels([fb.image for fb in galleon_frames(s, quick)]))
    return Item(SECTION, "cutaway_galleon.png",
                "A hull and its gun deck cut away to reveal two rows of cannons (Fig. 1), from "
                "three cameras; the cutaway follows the view. Ghost lines (g_max = 1, faded) "
                "show the removed front edge of the deck; the hull itself gives none: a smooth "
                "ellipsoid has no creases, and its silhouettes are not removed.")


def _office(out, s):
    house = building()
    room = _box((0.5, 0.3, 0.5), (5.6, 2.9, 6.5))       # invisible stand-in for room A
    furniture = [_box((1.5, 0.25, 2.0), (3.5, 1.0, 3.2)),
                 _box((4.0, 0.25, 4.5), (4.8, 1.6, 5.2))]
    cam = _camera((16.0, 11.0, 17.0), (5.0, 2.0, 3.5), s, s)
    a = render_cutaway(furniture, house, **cam, stand_ins=[room],
                       cutaway=Cutaway(angle=[0.3, 0.3, 0.3]), ghosts=GhostLines(distance=1.5))
    b = render_cutaway(furniture, house, **cam, stand_ins=[room], cutaway=Cutaway(angle=0.6),
                       ghosts=GhostLines(distance=1.5))
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
            frames.append(render_cutaway(target, wall, **cam, cutaway=Cutaway(
                angle=0.6, edge_compression=compression)).image)
        rows.append(_panels(frames))
    sep = np.ones((4, rows[0].shape[1], 3), np.float32)
    write_png(out / "cutaway_pan.png", np.concatenate([rows[0], sep, rows[1]], axis=0))
    return Item(SECTION, "cutaway_pan.png",
                "Camera pan (Fig. 7): the object of interest leaves the frame. Top: without "
                "edge compression the cut stays wide until the object is gone and then pops; "
                "bottom: with r = 0.1 it narrows toward the border (Sec. 5.4).")


def _fig10(out, s):
    room = [_box((-7, -0.2, -3), (7, 0, 3)),                       # floor
            _box((-7, 0, 1.0), (7, 3.2, 1.2)),                     # the wall facing the camera
            _box((-7, 0, -3), (7, 3.2, -2.8))]                     # back wall
    counter = _box((-0.8, 0, -2.8), (0.8, 0.9, -2.2))
    w, h = s, (3 * s) // 4
    cam = _camera((0.8, 3.0, 9.0), (-0.8, 0.8, -1.2), w, h)
    frames = []
    for x in (-3.8, -2.4, -1.4):        # the car drives toward the counter
        car = _box((x - 0.3, 0, -1.9), (x + 0.3, 0.35, -1.4))
        frames.append(render_cutaway([counter, car], room, **cam, cutaway=Cutaway(
            angle=0.28, floor_normal=(0, 1, 0)), ghosts=GhostLines(distance=0.8)).image)
    write_png(out / "cutaway_fig10.png", _panels(frames))
    return Item(SECTION, "cutaway_fig10.png",
                "Several objects of interest (Fig. 10): a kitchen counter and a small car behind "
                "a wall (θ = 0.28, floor constraint on). Far apart they cut two separate holes "
                "(left); as the car approaches the counter the two cutaway shapes merge into one "
                "(middle, right): D is the maximum over the seeds of both, and neither object "
                "cuts the other.")


def _plot(curves, w, h, xr, yr):
    """A small line plot: ``curves`` = [(x, y, rgb, thickness)], y down = farther; NaN breaks."""
    img = np.ones((h, w, 3), np.float32)
    img[[0, -1], :] = 0.6
    img[:, [0, -1]] = 0.6
    for x, y, rgb, th in curves:
        x, y = np.asarray(x, float), np.asarray(y, float)
        for i in range(len(x) - 1):
            if not np.all(np.isfinite([x[i], x[i + 1], y[i], y[i + 1]])):
                continue
            t = np.linspace(0.0, 1.0, 40)
            px = (x[i] + t * (x[i + 1] - x[i]) - xr[0]) / (xr[1] - xr[0]) * (w - 1)
            py = (y[i] + t * (y[i + 1] - y[i]) - yr[0]) / (yr[1] - yr[0]) * (h - 1)
            for dx in range(th):
                for dy in range(th):
                    c = np.round(px).astype(int) + dx
                    r = np.round(py).astype(int) + dy
                    ok = (c >= 0) & (c < w) & (r >= 0) & (r < h)
                    img[r[ok], c[ok]] = rgb
    return img


def _fig3(out, s):
    """Fig. 2–3: depth plots of one pixel row: rear hulls, the surface, the secondary wall."""
    slab = [_box((-3, -0.3, 0.6), (3, 0.3, 1.0))]
    ooi = [_box((-1.6, -0.25, -0.9), (-0.8, 0.25, -0.3)), _box((0.6, -0.25, -1.6), (1.2, 0.25, -1.0))]
    eye = (0.0, 0.0, 6.0)
    theta = 0.5
    cams = {"ortho": dict(view=look_at(eye, (0, 0, 0)), proj=orthographic(-3, 3, -1, 1, 2.0, 10.0),
                          width=s, height=s // 3),
            "persp": dict(view=look_at(eye, (0, 0, 0)), proj=perspective(40.0, 3.0, 2.0, 10.0),
                          width=s, height=s // 3)}
    panels = []
    grey, green, blue = (0.6, 0.6, 0.6), (0.2, 0.6, 0.25), (0.15, 0.3, 0.8)
    for name, cam in cams.items():
        rear = _render(ooi, raster=REAR_HULL, **cam)
        wall = _render(slab, **cam)
        z_i = np.where(rear.object_id >= 0, 2.0 * rear.depth.astype(np.float64) - 1.0, -1.0)
        d = cutaway_surface(rear.depth, rear.object_id, proj=cam["proj"], angle=theta,
                            edge_compression=None)
        row = cam["height"] // 2
        x, y = pixel_ndc(cam["height"], cam["width"])
        if name == "ortho":
            # (a) initialisation: the rear hulls punch into the near plane; (b) the surface
            zi, dd, zw = z_i[row], d[row], 2.0 * wall.depth[row].astype(np.float64) - 1.0
            xs = x[row]
            yr = (-1.05, 0.5)
            panels.append(_plot([(xs, zi, green, 2)], s, s // 2, (-1, 1), yr))
            panels.append(_plot([(xs, np.where(wall.object_id[row] >= 0, zw, np.nan), grey, 3),
                                 (xs, zi, green, 2), (xs, dd, blue, 2)], s, s // 2, (-1, 1), yr))
        else:
            # (c) perspective: D un-projected to eye space keeps its conical shape along the rays
            pd = unproject(x[row], y[row], d[row], cam["proj"])
            pi = unproject(x[row], y[row], z_i[row], cam["proj"])
            pw = unproject(x[row], y[row], 2.0 * wall.depth[row].astype(np.float64) - 1.0,
                           cam["proj"])
            rays = []
            for k in range(0, cam["width"], max(cam["width"] // 12, 1)):
                far = unproject(x[row, k:k + 1], y[row, k:k + 1], np.array([1.0]), cam["proj"])[0]
                rays.append(([0.0, far[0]], [0.0, -far[2]], (0.85, 0.85, 0.85), 1))
            curves = rays + [
                (pw[:, 0], np.where(wall.object_id[row] >= 0, -pw[:, 2], np.nan), grey, 3),
                (pi[:, 0], np.where(rear.object_id[row] >= 0, -pi[:, 2], np.nan), green, 2),
                (pd[:, 0], -pd[:, 2], blue, 2)]
            panels.append(_plot(curves, s, s // 2, (-3.5, 3.5), (1.8, 8.2)))
    write_png(out / "cutaway_fig3.png", _panels(panels))
    return Item(SECTION, "cutaway_fig3.png",
                "Depth plots of one pixel row (Fig. 2–3; depth grows downward): a wall (grey) in "
                "front of two objects of interest (green, their rear hulls). (a) Orthographic "
                "initialisation: the rear hulls punch into the near plane (NDC −1). (b) The "
                "cutaway surface D (blue), Eq. 2 as corrected (D-C1) with θ = 0.5: cones of "
                "half-angle θ, their maximum; the wall is discarded where it lies above the blue "
                "line. (c) Perspective with compensation, D un-projected to eye space (x, −z): "
                "the cones follow the camera rays (light grey).")


def _surface(out, s):
    """The image-space core: seeds, D by jump flooding, and its error against brute force."""
    core = [icosphere(2, radius=0.3), _box((0.2, -0.1, 0.2), (0.5, 0.2, 0.5))]
    cam = _camera((2.6, 1.6, 3.0), (0, 0, 0), s, s)
    rear = _render(core, raster=REAR_HULL, **cam)
    seeds = np.where(rear.object_id >= 0, 2.0 * rear.depth.astype(np.float64) - 1.0, -np.inf)
    slope, _ = seed_slopes(np.where(np.isfinite(seeds), seeds, -1.0), np.full(seeds.shape, 0.5),
                        proj=cam["proj"], edge_compression=None)
    sampling = tangent_sampling(cam["proj"], s, s)
    ref = np.maximum(exact(seeds, slope, sampling=sampling), -1.0)
    jfa = np.maximum(jump_flood(seeds, slope, sampling=sampling, variant="jfa"), -1.0)
    ch = np.maximum(chamfer(seeds, slope, sampling=sampling), -1.0)
    eye_ref = ndc_to_eye_depth(ref, cam["proj"])
    lo, hi = eye_ref.min(), eye_ref.max()

    def grey(e):
        g = 1.0 - (ndc_to_eye_depth(e, cam["proj"]) - lo) / max(hi - lo, 1e-12)
        return np.repeat(np.clip(g, 0, 1)[..., None], 3, axis=-1).astype(np.float32)

    def err(e):
        r = np.clip(np.abs(ndc_to_eye_depth(e, cam["proj"]) - eye_ref) / 0.05, 0, 1)
        img = np.ones((s, s, 3), np.float32)
        img[..., 1] -= r
        img[..., 2] -= r
        return img

    seed_img = grey(np.where(np.isfinite(seeds), seeds, -1.0))
    write_png(out / "cutaway_surface.png", _panels([seed_img, grey(ref), err(jfa), err(ch)]))
    return Item(SECTION, "cutaway_surface.png",
                "The cutaway surface in image space (Sec. 3, 5.1) for the nested-shells camera, "
                "θ = 0.5: (a) rear-hull seeds z_I (greater depth test, near elsewhere); (b) D by "
                "brute force (`exact`), eye depth as grey (near = white); (c) where plain jump "
                "flooding differs from it (red, saturating at 0.05 eye units); (d) the same for "
                "the 5×5 chamfer.")


def _buffer(out, s):
    """Sec. 6: a cutaway buffer smaller than the frame, upsampled bilinearly."""
    shells = nested_shells((1.2, 1.05, 0.8, 0.68), subdivisions=3)
    core = [icosphere(3, radius=0.3), _box((0.2, -0.1, 0.2), (0.5, 0.2, 0.5))]
    cam = _camera((2.6, 1.6, 3.0), (0, 0, 0), s, (3 * s) // 4)
    imgs = [render_cutaway(core, shells, **cam, cutaway=Cutaway(angle=0.5, buffer_size=size)).image
            for size in (None, (s // 4, s // 4))]
    write_png(out / "cutaway_buffer.png", _panels(imgs))
    return Item(SECTION, "cutaway_buffer.png",
                "Cutaway buffer resolution (Sec. 6): the frame's own (left) and a square buffer "
                "of a quarter of the width (right, non-square pixels), upsampled bilinearly: the "
                "smooth surface survives the low resolution.")


def render(out_dir: pathlib.Path, *, quick: bool = False) -> list[Item]:
    """Render the cutaway gallery pictures into ``out_dir``; ``quick`` uses small images."""
    out = pathlib.Path(out_dir)
    s = 96 if quick else 360
    items = [_shells(out, s), _fig3(out, s), _surface(out, s // 2 if not quick else s),
             _buffer(out, s), _fig4(out, (3 * s) // 4 if not quick else s),
             _fig5(out, s // 2 if not quick else s)]
    items += _radiators(out, s)
    items.append(_galleon(out, s, quick))
    items.append(_office(out, s))
    items.append(_pan(out, s))
    items.append(_fig10(out, s))
    from .multisample import picture
    items += picture("cutaway", SECTION, out, quick)
    return items
