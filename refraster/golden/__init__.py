"""Golden images: canonical scenes, scene packages, generation, comparison and reports.

refraster is the reference another backend (a GPU implementation of the same techniques) is
checked against. :func:`generate` renders the registered scenes into a golden directory (the
buffers, PNG previews, a scene package a GPU backend loads without Python, and a manifest with
versions, tolerances and sha256 of every file); :func:`compare` checks a candidate directory
against it and writes an HTML report. ``refraster golden generate|compare`` are the command-line
twins (:mod:`refraster.golden.cli`). See ``docs/golden.md`` and ``docs/golden-schema.md``.
"""

from .compare.run import (EXIT_FAIL, EXIT_PASS, EXIT_UNUSABLE, CandidateError, Comparison,
                      GoldenError, compare, load_manifest, position_deviation)
from .generate import generate
from .scenes import (DEFAULT_RASTER, SCENES, Draw, GoldenScene, available_scenes,
                     load_scene_file, prepare_draws, register_scene, register_technique,
                     render_scene)
from .io.schema import (MANIFEST_SCHEMA, MANIFEST_SCHEMA_VERSION, SCENE_SCHEMA,
                     SCENE_SCHEMA_VERSION, SchemaError)

__all__ = [
    "generate", "compare", "load_manifest", "position_deviation", "Comparison", "GoldenError",
    "CandidateError", "EXIT_PASS", "EXIT_FAIL", "EXIT_UNUSABLE", "SCENES", "Draw", "GoldenScene",
    "available_scenes", "load_scene_file", "prepare_draws", "register_scene",
    "register_technique", "render_scene", "DEFAULT_RASTER", "SCENE_SCHEMA", "MANIFEST_SCHEMA",
    "SCENE_SCHEMA_VERSION", "MANIFEST_SCHEMA_VERSION", "SchemaError",
]
