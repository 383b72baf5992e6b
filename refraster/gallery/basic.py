"""Gallery section "basic": every canonical solid, shaded, and its G-buffer channels.

For each solid of :data:`refraster.scenes.SOLIDS`: the headlight-shaded colour, the depth (as
normalized linear depth), the eye-space normals and the primitive ids, each as a PNG under
``basic/``. The nested shells are drawn once more with the half x > 0 discarded by a fragment
stage, so that their cavities show.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Item

__all__ = ["render", "depth_image", "normal_image", "id_image"]

SECTION = "basic"
FULL_SIZE = (512, 384)
QUICK_SIZE = (128, 96)


def depth_image(fb):
    """Normalized linear depth fitted to the visible surface: nearest black, farthest light
    grey (0.85), background white."""
    import refraster
    covered = np.isfinite(fb.eye_depth)
    if not covered.any():
        return np.ones(fb.eye_depth.shape, np.float32)
    near, far = float(fb.eye_depth[covered].min()), float(fb.eye_depth[covered].max())
    d = refraster.normalized_linear_depth(fb, near, max(far, near * (1 + 1e-6) + 1e-9))
    return np.where(covered, 0.85 * d, 1.0).astype(np.float32)


def normal_image(fb):
    """Eye-space normals as colours ``(n + 1) / 2``; background white."""
    rgb = 0.5 * (fb.normal.astype(np.float32) + 1.0)
    return np.where(fb.mask[..., None], rgb, 1.0).astype(np.float32)


def id_image(ids):
    """Distinct, deterministic colours for non-negative ids (Knuth's multiplicative hash); −1
    (background) white."""
    ids = np.asarray(ids)
    h = (ids.astype(np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFFFF)
    rgb = np.stack([(h >> np.uint64(s)) & np.uint64(0xFF) for s in (0, 8, 16)], axis=-1)
    # lift into [0.2, 0.9] so no id is mistaken for the white background or black edges
    rgb = 0.2 + 0.7 * rgb.astype(np.float32) / 255.0
    return np.where((ids >= 0)[..., None], rgb, 1.0).astype(np.float32)


def _write_channels(out_dir, stem, fb, label):
    from ..io import write_png
    channels = [
        ("shaded", fb.color, f"{label}: headlight shading"),
        ("depth", depth_image(fb),
         f"{label}: depth (normalized linear depth over the visible range, near = black)"),
        ("normal", normal_image(fb), f"{label}: eye-space normals as (n + 1) / 2"),
        ("prim_id", id_image(fb.prim_id), f"{label}: primitive ids (hashed colours)"),
    ]
    items = []
    for channel, image, caption in channels:
        filename = f"{SECTION}/{stem}_{channel}.png"
        write_png(Path(out_dir) / filename, image)
        items.append(Item(SECTION, filename, caption))
    return items


def render(out_dir, *, quick=False):
    """Render the section into ``out_dir``; return its :class:`~refraster.gallery.Item` list."""
    import refraster
    from ..camera import frame_bounds
    from ..scenes import SOLIDS, solid

    width, height = QUICK_SIZE if quick else FULL_SIZE
    items = []
    for name in SOLIDS:
        mesh = solid(name, quick=quick)
        cam = frame_bounds(mesh.bounds, width=width, height=height)
        fb = refraster.render(mesh, **cam.kwargs)
        label = f"{name} ({len(mesh.faces):,} faces)"
        items += _write_channels(out_dir, name, fb, label)
        if name == "nested_shells":
            fb = refraster.render(mesh, **cam.kwargs,
                                  fragment_stage=lambda f: f.world_position()[:, 0] <= 0.0)
            items += _write_channels(out_dir, "nested_shells_cut", fb,
                                     f"{label}, half x > 0 discarded")
    return items
