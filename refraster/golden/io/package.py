"""Scene packages: what a GPU backend loads to render a golden scene without Python.

Layout (paths relative to the package directory; ``docs/golden-schema.md`` has every field)::

    scene.json            camera, viewport, raster state, draws, shading, maps, parameters
    meshes/<draw>.ply     binary little-endian PLY: float32 x y z [nx ny nz], int32 faces
    maps/<map>.npy        exact map values (NumPy .npy, no pickle)
    maps/<map>.png        16-bit PNG of the same map (see its "png_encoding")

Vertices are float32 in the PLY and the golden was rendered from exactly those values
(:func:`refraster.golden.scenes.prepare_draws`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ... import io as rio
from ...io import npy_bytes, npz_bytes
from ...camera import is_perspective, near_far
from ...framebuffer import PALETTE
from ...raster.gbuffer import AMBIENT, DIFFUSE, SHININESS, SPECULAR
from .schema import SCENE_SCHEMA, SCENE_SCHEMA_VERSION, validate

__all__ = ["export_package", "scene_document", "npz_bytes", "npy_bytes", "sha256_file",
           "SHADING"]

#: The shading of :attr:`refraster.Framebuffer.color` as numbers (``scene.json`` "shading").
SHADING = dict(model="headlight", ambient=AMBIENT, diffuse=DIFFUSE, specular=SPECULAR,
               shininess=SHININESS, palette=PALETTE.tolist())


def sha256_file(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _ply_bytes(draw):
    import trimesh
    mesh = trimesh.Trimesh(draw.mesh.vertices, draw.mesh.faces, process=False)
    if draw.normals is not None:
        mesh.vertex_normals = draw.normals
    return trimesh.exchange.ply.export_ply(mesh, encoding="binary",
                                           vertex_normal=draw.normals is not None,
                                           include_attributes=False)


def _map_png(values):
    """16-bit PNG encoding of a map: unorm16, snorm16 or range16 (with its range)."""
    a = np.asarray(values, np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError("maps must be finite to be exported as PNG")
    lo, hi = (float(a.min()), float(a.max())) if a.size else (0.0, 1.0)
    if lo >= 0.0 and hi <= 1.0:
        enc, x = "unorm16: value = png / 65535", a
    elif lo >= -1.0 and hi <= 1.0:
        enc, x = "snorm16: value = png / 65535 * 2 - 1", a * 0.5 + 0.5
    else:
        hi = hi if hi > lo else lo + 1.0
        enc = f"range16: value = {lo!r} + png / 65535 * ({hi!r} - {lo!r})"
        x = (a - lo) / (hi - lo)
    png = (np.clip(x, 0.0, 1.0) * 65535.0 + 0.5).astype(np.uint16)
    if png.ndim == 3 and png.shape[2] == 2:
        png = np.concatenate([png, np.zeros(png.shape[:2] + (1,), np.uint16)], axis=2)
    return png, enc


def is_reversed(proj):
    """Whether a perspective or orthographic ``proj`` maps nearer points to larger depths
    (reversed-Z): ``z_ndc = −a + b/d`` at distance ``d`` (perspective: reversed when ``b > 0``),
    ``−a·d + b`` (orthographic: when ``a > 0``)."""
    a, b = float(proj[2, 2]), float(proj[2, 3])
    return b > 0.0 if is_perspective(proj) else a > 0.0


def camera_near_far(proj, depth_range="negative_one_to_one"):
    """(near, far) distances of a projection built for ``depth_range``, reversed or not
    (:func:`is_reversed`); far is ``None`` for an infinite far plane (``scene.json``)."""
    if depth_range == "negative_one_to_one" and not is_reversed(proj):
        near, far = near_far(proj)
    else:
        near, far = near_far(proj, reversed=is_reversed(proj), depth_range=depth_range)
    return float(near), (float(far) if np.isfinite(far) else None)


def scene_document(name, scene, raster, map_entries, *, exact_ties=False):
    """The ``scene.json`` document of a :class:`GoldenScene` (validated against the schema).
    ``exact_ties``: the golden decides pixel centres exactly on some edges by
    ``raster.fill_rule`` (written as ``"exact_ties": true``; absent otherwise)."""
    cam = scene.camera
    near, far = camera_near_far(cam.proj, raster.get("depth_range", "negative_one_to_one"))
    doc = {
        "schema": "refraster.scene",
        "schema_version": SCENE_SCHEMA_VERSION,
        "name": name,
        "technique": scene.technique,
        "description": scene.description,
        "viewport": {"width": cam.width, "height": cam.height},
        "camera": {"view": cam.view.tolist(), "projection": cam.proj.tolist(),
                   "kind": "perspective" if is_perspective(cam.proj) else "orthographic",
                   "near": near, "far": far},
        "raster": dict(raster),
        "draws": [{"object_id": k, "name": d.name, "mesh": f"meshes/{d.name}.ply",
                   "model": np.asarray(d.model, np.float64).tolist(),
                   "n_vertices": d.mesh.n_vertices, "n_faces": d.mesh.n_faces}
                  for k, d in enumerate(scene.draws)],
        "shading": {**SHADING, "background": [1.0, 1.0, 1.0]},
        "maps": map_entries,
        "parameters": scene.parameters,
    }
    if exact_ties:
        doc["exact_ties"] = True
    return validate(doc, SCENE_SCHEMA)


def export_package(directory, name, scene, raster, *, exact_ties=False):
    """Write the scene package of ``scene`` into ``directory``; return the files written
    (paths relative to ``directory``, POSIX). ``exact_ties`` as :func:`scene_document`."""
    directory = Path(directory)
    written = []
    for d in scene.draws:
        rel = f"meshes/{d.name}.ply"
        rio.atomic_write_bytes(directory / rel, _ply_bytes(d))
        written.append(rel)
    map_entries = {}
    for key in sorted(scene.maps):
        values = np.asarray(scene.maps[key])
        png, encoding = _map_png(values)
        rio.atomic_write_bytes(directory / f"maps/{key}.npy", npy_bytes(values))
        rio.write_png(directory / f"maps/{key}.png", png)
        written += [f"maps/{key}.npy", f"maps/{key}.png"]
        map_entries[key] = {"npy": f"maps/{key}.npy", "png": f"maps/{key}.png",
                            "shape": list(values.shape), "dtype": str(values.dtype),
                            "png_encoding": encoding}
    rio.write_json(directory / "scene.json", scene_document(name, scene, raster, map_entries,
                                                          exact_ties=exact_ties))
    written.append("scene.json")
    return written
