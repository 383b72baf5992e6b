"""The versioned JSON schemas of a scene package (``scene.json``) and a golden ``manifest.json``.

Both are written as JSON Schema (a draft 2020-12 subset: ``type``, ``properties``,
``required``, ``additionalProperties``, ``propertyNames``, ``items``, ``minItems``,
``maxItems``, ``enum``, ``const``, ``minimum``, ``maximum``, ``pattern``) so that a backend in any
language can validate with its own JSON Schema library; :func:`validate` checks that subset here
without a dependency. ``docs/golden-schema.md`` is the prose twin of these dicts.

Versioning: ``schema_version`` is an integer. A reader accepts every version up to the one it
knows (:data:`SCENE_SCHEMA_VERSION`, :data:`MANIFEST_SCHEMA_VERSION`) and refuses a newer one with
a message saying so, before it looks at anything else in the file. Adding an optional field
keeps the version; renaming, removing or changing the meaning of a field bumps it.
"""

from __future__ import annotations

import re

__all__ = [
    "SCENE_SCHEMA_VERSION", "MANIFEST_SCHEMA_VERSION", "SCENE_SCHEMA", "MANIFEST_SCHEMA",
    "SchemaError", "validate", "check_version", "is_safe_relpath", "OBJECT_ID_MAX",
    "CANDIDATE_MARKER_SCHEMA", "REPORT_MARKER_SCHEMA", "LISTING_SCHEMA",
]

SCENE_SCHEMA_VERSION = 1
#: 2: id buffers state the ids their scene can produce (``ids``), checked by the compare's
#: domain checks; a version-1 golden lacks them and is refused (regenerate it).
#: 3: technique scenes carry allowances of their own ("Goldens with teeth (2)": the
#: ``layers`` check of layered depth images, ``tolerance.npz``'s ``ldi_*`` arrays); a
#: version-2 golden checks them with the old fraction-of-pixels profile and is refused.
MANIFEST_SCHEMA_VERSION = 3
#: The oldest manifest version this refraster reads.
MANIFEST_SCHEMA_OLDEST = 3


class SchemaError(ValueError):
    """A JSON document does not follow its schema (the message gives the JSON path)."""


#: A relative POSIX path that stays inside its directory: no leading "/", no "..", no "\\",
#: no drive letter, no empty or "." segments.
_SEGMENT = r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*"
RELPATH_PATTERN = rf"^{_SEGMENT}(/{_SEGMENT})*$"

#: Largest ``object_id`` of a draw: the id buffers are int32, and a backend may store
#: ``object_id + 1`` (0 for "no draw"), which must fit too.
OBJECT_ID_MAX = 2 ** 31 - 2

_MAT4 = {
    "type": "array", "minItems": 4, "maxItems": 4,
    "items": {"type": "array", "minItems": 4, "maxItems": 4, "items": {"type": "number"}},
}
_VEC3 = {"type": "array", "minItems": 3, "maxItems": 3, "items": {"type": "number"}}
_RELPATH = {"type": "string", "pattern": RELPATH_PATTERN}
_NAME = {"type": "string", "pattern": r"^[a-z0-9][a-z0-9_]*$"}
_SHAPE = {"type": "array", "minItems": 1, "maxItems": 4,
          "items": {"type": "integer", "minimum": 0}}

#: ``scene.json``: everything a backend needs to render the scene without Python.
SCENE_SCHEMA = {
    "$id": "refraster.scene",
    "type": "object",
    "required": ["schema", "schema_version", "name", "technique", "description", "viewport",
                 "camera", "raster", "draws", "shading", "maps", "parameters"],
    "additionalProperties": False,
    "properties": {
        "schema": {"const": "refraster.scene"},
        "schema_version": {"type": "integer", "minimum": 1},
        "name": _NAME,
        "technique": {"type": "string"},
        "description": {"type": "string"},
        "viewport": {
            "type": "object", "required": ["width", "height"], "additionalProperties": False,
            "properties": {"width": {"type": "integer", "minimum": 1},
                           "height": {"type": "integer", "minimum": 1}},
        },
        "camera": {
            "type": "object", "required": ["view", "projection", "kind", "near", "far"],
            "additionalProperties": False,
            "properties": {"view": _MAT4, "projection": _MAT4,
                           "kind": {"enum": ["perspective", "orthographic"]},
                           "near": {"type": "number"},
                           # null: an infinite far plane (JSON has no infinity)
                           "far": {"type": ["number", "null"]}},
        },
        "raster": {
            "type": "object",
            "required": ["subpixel_bits", "fill_rule", "precision", "cull", "depth_func",
                         "front_face", "clear_depth", "normals"],
            "additionalProperties": False,
            "properties": {
                "subpixel_bits": {"type": "integer", "minimum": 0, "maximum": 16},
                "fill_rule": {"enum": ["llvmpipe", "top_left"]},
                "precision": {"enum": ["float32", "float64"]},
                "cull": {"enum": ["none", "back", "front"]},
                "depth_func": {"enum": ["less", "lequal", "greater", "gequal", "equal",
                                        "notequal", "always", "never"]},
                "front_face": {"enum": ["ccw", "cw"]},
                "clear_depth": {"type": "number", "minimum": 0, "maximum": 1},
                "normals": {"enum": ["flat", "smooth"]},
                # the API conventions (RasterState's names and values; optional: a package
                # without them is in OpenGL's conventions, the defaults)
                "depth_range": {"enum": ["negative_one_to_one", "zero_to_one"]},
                "origin": {"enum": ["lower_left", "upper_left"]},
                "ndc_y": {"enum": ["up", "down"]},
                "depth_clamp": {"type": "boolean"},
                "depth_format": {"enum": ["float32", "unorm24", "unorm16"]},
                # multisampling (optional: a package without them has one sample per pixel)
                "samples": {"enum": [1, 2, 4, 8, 16]},
                # "standard", "gl_llvmpipe" or [[x, y], ...] in 1/16 pixel (RasterState checks
                # the names, the count and the range)
                "sample_locations": {"type": ["string", "array"], "maxItems": 16,
                                     "items": {"type": "array", "minItems": 2, "maxItems": 2,
                                               "items": {"type": "integer", "minimum": 0,
                                                         "maximum": 15}}},
                "interpolation": {"enum": ["center", "centroid", "sample"]},
            },
        },
        "draws": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["object_id", "name", "mesh", "model", "n_vertices", "n_faces"],
                "additionalProperties": False,
                "properties": {
                    "object_id": {"type": "integer", "minimum": 0, "maximum": OBJECT_ID_MAX},
                    "name": _NAME,
                    "mesh": _RELPATH,
                    "model": _MAT4,
                    "n_vertices": {"type": "integer", "minimum": 0},
                    "n_faces": {"type": "integer", "minimum": 0},
                },
            },
        },
        "shading": {
            "type": "object",
            "required": ["model", "ambient", "diffuse", "specular", "shininess", "palette",
                         "background"],
            "additionalProperties": False,
            "properties": {
                "model": {"const": "headlight"},
                "ambient": {"type": "number"}, "diffuse": {"type": "number"},
                "specular": {"type": "number"}, "shininess": {"type": "number"},
                "palette": {"type": "array", "minItems": 1, "items": _VEC3},
                "background": _VEC3,
            },
        },
        "maps": {
            "type": "object",
            "propertyNames": _NAME,
            "additionalProperties": {
                "type": "object", "required": ["npy", "png", "shape", "dtype", "png_encoding"],
                "additionalProperties": False,
                "properties": {
                    "npy": _RELPATH, "png": _RELPATH, "shape": _SHAPE,
                    "dtype": {"type": "string"},
                    "png_encoding": {"type": "string"},
                    "description": {"type": "string"},
                },
            },
        },
        "parameters": {"type": "object"},
        "exact_ties": {"type": "boolean"},
    },
}

_TOLERANCE = {
    "type": "object",
    "required": ["threshold", "max_fraction", "deviation_radius"],
    "additionalProperties": False,
    "properties": {
        "threshold": {"type": "number", "minimum": 0},
        "slope": {"type": "number", "minimum": 0},
        "max_fraction": {"type": "number", "minimum": 0, "maximum": 1},
        "deviation_radius": {"type": "integer", "minimum": 0, "maximum": 8},
        "max_abs": {"type": ["number", "null"], "minimum": 0},
        "min_psnr": {"type": ["number", "null"]},
        "max_flip_mean": {"type": ["number", "null"], "minimum": 0},
    },
}

_ARRAY_NAME = {"type": "string", "pattern": r"^[a-z0-9][a-z0-9_]*$"}

#: Per buffer: which tolerant checks apply and which arrays of ``tolerance.npz`` they read
#: (optional; added without a version bump).
_TOLERANT = {
    "type": "object",
    "required": ["checks"],
    "additionalProperties": False,
    "properties": {
        "checks": {"type": "array", "minItems": 1,
                   "items": {"enum": ["coverage", "id", "interval", "angle", "masked",
                                      "face", "layers", "bounds", "clip"]}},
        "layer": {"enum": ["depth", "prim_id", "front_facing", "count"]},
        "lo": _ARRAY_NAME, "hi": _ARRAY_NAME, "angle": _ARRAY_NAME, "may": _ARRAY_NAME,
        "zero": _ARRAY_NAME,
        # a per-sample buffer of a multisampled golden: its checks read the arrays of that
        # sample (``s<sample>_<name>``; allowances/samples.py)
        "sample": {"type": "integer", "minimum": 0, "maximum": 15},
    },
}

#: Per scene: the allowance arrays (``<scene>/tolerance.npz``) and how they were derived.
_ALLOWANCES = {
    "type": "object",
    "required": ["file", "method", "eps", "depth_eps", "normal_tol", "color_tol", "may_radius",
                 "min_subpixel_bits", "arrays"],
    "additionalProperties": False,
    "properties": {
        "file": _RELPATH,
        "method": {"enum": ["geometry", "decision", "dilated"]},
        "eps": {"type": "number", "minimum": 0},
        "depth_eps": {"type": "number", "minimum": 0},
        "normal_tol": {"type": "number", "minimum": 0},
        "color_tol": {"type": "number", "minimum": 0},
        "may_radius": {"type": "integer", "minimum": 0},
        "min_subpixel_bits": {"type": "integer", "minimum": 0},
        "arrays": {
            "type": "object", "propertyNames": _ARRAY_NAME,
            "additionalProperties": {
                "type": "object", "required": ["shape", "dtype"], "additionalProperties": False,
                "properties": {"shape": _SHAPE,
                               "dtype": {"enum": ["int8", "int32", "bool", "float32"]}},
            },
        },
    },
}

#: ``manifest.json``: the index of a golden directory.
MANIFEST_SCHEMA = {
    "$id": "refraster.golden",
    "type": "object",
    "required": ["schema", "schema_version", "generator", "raster", "scenes", "files"],
    "additionalProperties": False,
    "properties": {
        "schema": {"const": "refraster.golden"},
        "schema_version": {"type": "integer", "minimum": 1},
        "generator": {
            "type": "object", "required": ["refraster", "numpy", "numba", "python"],
            "additionalProperties": {"type": "string"},
        },
        "raster": {
            "type": "object", "required": ["subpixel_bits", "fill_rule"],
            "additionalProperties": False,
            "properties": {"subpixel_bits": {"type": "integer", "minimum": 0},
                           "fill_rule": {"type": "string"}},
        },
        # optional, added without a version bump: the candidate's declared sub-pixel bits the
        # allowances assume (a manifest without it was generated for 4)
        "candidate": {
            "type": "object", "required": ["subpixel_bits"], "additionalProperties": False,
            "properties": {"subpixel_bits": {"type": "integer", "minimum": 4, "maximum": 8}},
        },
        "scenes": {
            "type": "object",
            "propertyNames": _NAME,
            "additionalProperties": {
                "type": "object",
                "required": ["technique", "description", "package", "buffers_file", "buffers",
                             "parameters"],
                "additionalProperties": False,
                "properties": {
                    "technique": {"type": "string"},
                    "description": {"type": "string"},
                    "package": _RELPATH,
                    "buffers_file": _RELPATH,
                    "parameters": {"type": "object"},
                    "buffers": {
                        "type": "object",
                        "propertyNames": _NAME,
                        "additionalProperties": {
                            "type": "object",
                            "required": ["shape", "dtype", "kind", "preview", "tolerance"],
                            "additionalProperties": False,
                            "properties": {
                                "shape": _SHAPE,
                                "dtype": {"enum": ["float32", "float64", "int32", "int64",
                                                   "uint8", "uint16", "bool"]},
                                "kind": {"enum": ["unorm", "snorm", "float", "id", "bool",
                                                  "color"]},
                                "preview": _RELPATH,
                                "tolerance": {
                                    "type": "object",
                                    "propertyNames": _NAME,
                                    "additionalProperties": _TOLERANCE,
                                },
                                "tolerant": _TOLERANT,
                                "ids": {"type": "array", "minItems": 2, "maxItems": 2,
                                        "items": {"type": "integer"}},
                            },
                        },
                    },
                    "allowances": _ALLOWANCES,
                },
            },
        },
        "files": {
            "type": "object",
            "propertyNames": _RELPATH,
            "additionalProperties": {"type": "string", "pattern": r"^[0-9a-f]{64}$"},
        },
    },
}

_FILES = {
    "type": "object",
    "propertyNames": _RELPATH,
    "additionalProperties": {"type": "string", "pattern": r"^[0-9a-f]{64}$"},
}

#: ``.refraster-candidate``: the marker of a candidate directory (``golden candidate``), as
#: far as it is trusted before a candidate is replaced (other fields are kept as written).
CANDIDATE_MARKER_SCHEMA = {
    "type": "object",
    "required": ["written_by", "files"],
    "properties": {
        "written_by": {"type": "string"},
        "files": _FILES,
        "backend": {"type": "string"},
        "renderer": {"type": "string"},
        "golden": {"type": "string"},
        "faults": {"type": "array", "items": {"type": "string"}},
        "rendered": {"type": "array", "items": _NAME},
        "skipped": {"type": "object", "propertyNames": _NAME,
                    "additionalProperties": {"type": "string"}},
    },
}

#: ``.refraster-report``: the marker of a report directory (``golden compare --report``).
REPORT_MARKER_SCHEMA = {
    "type": "object",
    "required": ["written_by", "files"],
    "properties": {"written_by": {"type": "string"}, "files": _FILES},
}

#: What a writer trusts of a golden's ``manifest.json`` before it replaces the golden (the
#: golden reader checks all of it against :data:`MANIFEST_SCHEMA`).
LISTING_SCHEMA = {"type": "object", "required": ["files"], "properties": {"files": _FILES}}

#: C0 and C1 control characters and DEL.
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")

_TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    "boolean": lambda v: isinstance(v, bool),
    "null": lambda v: v is None,
}


def _check(value, schema, path):
    if "const" in schema and value != schema["const"]:
        raise SchemaError(f"{path}: must be {schema['const']!r}, got {value!r}")
    if "enum" in schema and value not in schema["enum"]:
        raise SchemaError(f"{path}: must be one of {schema['enum']}, got {value!r}")
    if "type" in schema:
        types = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
        if not any(_TYPES[t](value) for t in types):
            raise SchemaError(f"{path}: must be of type {'/'.join(types)}, "
                              f"got {type(value).__name__}")
    if _TYPES["number"](value):
        if value != value or value in (float("inf"), float("-inf")):
            raise SchemaError(f"{path}: must be finite, got {value}")
        if "minimum" in schema and value < schema["minimum"]:
            raise SchemaError(f"{path}: must be >= {schema['minimum']}, got {value}")
        if "maximum" in schema and value > schema["maximum"]:
            raise SchemaError(f"{path}: must be <= {schema['maximum']}, got {value}")
    if isinstance(value, str) and "pattern" in schema:
        # a control character never matches a pattern here; the check first, because Python's
        # "$" also matches before a final newline (ECMA-262's, the schema's dialect, does not)
        if _CONTROL.search(value):
            raise SchemaError(f"{path}: {value!r} contains a control character")
        if not re.search(schema["pattern"], value):
            raise SchemaError(f"{path}: {value!r} does not match {schema['pattern']}")
    if isinstance(value, list):
        if len(value) < schema.get("minItems", 0) or len(value) > schema.get("maxItems", 1 << 62):
            raise SchemaError(f"{path}: has {len(value)} items, expected "
                              f"{schema.get('minItems', 0)}..{schema.get('maxItems', 'any')}")
        if "items" in schema:
            for i, item in enumerate(value):
                _check(item, schema["items"], f"{path}[{i}]")
    if isinstance(value, dict):
        for key in schema.get("required", ()):
            if key not in value:
                raise SchemaError(f"{path}: missing required field {key!r}")
        props = schema.get("properties", {})
        extra = schema.get("additionalProperties", True)
        for key, item in value.items():
            if "propertyNames" in schema:
                _check(key, schema["propertyNames"], f"{path} key {key!r}")
            if key in props:
                _check(item, props[key], f"{path}.{key}")
            elif extra is False:
                raise SchemaError(f"{path}: unknown field {key!r}")
            elif isinstance(extra, dict):
                _check(item, extra, f"{path}.{key}")


def validate(document, schema):
    """Check ``document`` (parsed JSON) against ``schema``; raise :class:`SchemaError` naming
    the first offending JSON path (``$.scenes.cube.buffers.depth.shape[0]``)."""
    _check(document, schema, "$")
    return document


def check_version(document, *, kind, supported, what, oldest=1):
    """Refuse a document of another kind, of a newer ``schema_version`` than ``supported`` or
    of an older one than ``oldest``."""
    if not isinstance(document, dict):
        raise SchemaError(f"{what}: expected a JSON object, got {type(document).__name__}")
    if document.get("schema") != kind:
        raise SchemaError(f"{what}: not a {kind} document (schema = {document.get('schema')!r})")
    version = document.get("schema_version")
    if not _TYPES["integer"](version) or version < 1:
        raise SchemaError(f"{what}: schema_version must be a positive integer, got {version!r}")
    if version > supported:
        raise SchemaError(
            f"{what}: schema_version {version} is newer than this refraster understands "
            f"(up to {supported}); upgrade refraster to read it")
    if version < oldest:
        raise SchemaError(
            f"{what}: schema_version {version} is older than this refraster reads (from "
            f"{oldest}); regenerate the golden with `refraster golden generate`")
    return version


def is_safe_relpath(path):
    """True for a relative path that cannot leave its directory (see :data:`RELPATH_PATTERN`)."""
    return isinstance(path, str) and re.fullmatch(RELPATH_PATTERN, path) is not None
