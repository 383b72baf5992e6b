"""Tolerances: per scene and buffer, stored in the manifest under named profiles, overridable.

A tolerance is a dict::

    threshold         a pixel is "over" when its error (max over channels of |ref − cand|)
                      exceeds ``threshold + slope · local_variation(ref)``
    slope             in pixels: forgives the change a shift of ``slope`` pixels makes
                      (:func:`refraster.golden.compare.metrics.local_variation`); 0 disables
    max_fraction      the largest allowed fraction of failing pixels
    deviation_radius  N ≥ 0: an "over" pixel is forgiven when a matching pixel lies within N
                      pixels (Chebyshev distance) in both directions — see
                      :func:`refraster.golden.compare.metrics.position_deviation`; 0 disables
    max_abs           optional limit on the largest error of all pixels
    min_psnr          optional lower limit on PSNR (dB)
    max_flip_mean     optional limit on the mean FLIP error (colour buffers)

Profiles
--------
``exact``
    Bit-exact: what refraster itself must reproduce (another thread count, another run).
``conformant``
    What a conformant OpenGL/Vulkan implementation with 8 sub-pixel bits needs: float32
    transforms in another order move depth by ~1e-7 and flip pixel centres lying within
    ~1e-3 px of an edge, so every buffer may differ at a pixel that has a matching pixel one
    pixel away, and values may differ by the float32 interpolation error. Numbers measured with
    Mesa llvmpipe in ``tests/test_golden_llvmpipe.py`` (``docs/golden.md`` has them).
"""

from __future__ import annotations

from ..io.schema import SchemaError, validate, _TOLERANCE

__all__ = ["PROFILES", "default_tolerances", "parse_override", "apply_overrides", "TOLERANCE_KEYS"]

TOLERANCE_KEYS = tuple(_TOLERANCE["properties"])

_EXACT = dict(threshold=0.0, slope=0.0, max_fraction=0.0, deviation_radius=0, max_abs=None,
              min_psnr=None, max_flip_mean=None)


#: Fraction of pixels a conformant GPU may get "wrong" beyond the position deviation: a pixel
#: centre on a silhouette where a front and a back face meet at equal depth (to ~1e-5) goes to
#: either face (llvmpipe: 1 pixel of 19 200 on render_fluted_column, 1 of 27 648 on
#: render_crank).
TIES = 2e-4


def _conformant(threshold, slope=0.0, max_fraction=TIES, **extra):
    return dict(_EXACT, threshold=threshold, slope=slope, max_fraction=max_fraction,
                deviation_radius=1, **extra)


#: Conformant-GPU tolerances of the G-buffer channels, by buffer name.
CONFORMANT = {
    "depth": _conformant(1e-6, 1.0 / 256.0),
    "eye_depth": _conformant(1e-5, 0.02),
    "normal": _conformant(1e-3, 0.02),
    "prim_id": _conformant(0.0),
    "object_id": _conformant(0.0),
    "front_facing": _conformant(0.0),
    "barycentric": _conformant(1e-3, 0.05, max_fraction=0.01),
    "color": _conformant(2.0 / 255.0, 0.02, max_flip_mean=0.01),
}
#: …and by kind for other buffers.
CONFORMANT_BY_KIND = {
    "unorm": _conformant(1e-3, 0.02), "snorm": _conformant(1e-3, 0.02),
    "float": _conformant(1e-5, 0.02), "id": _conformant(0.0), "bool": _conformant(0.0),
    "color": _conformant(2.0 / 255.0, 0.02, max_flip_mean=0.01),
}
PROFILES = ("exact", "conformant")


def default_tolerances(name, kind, overrides=None):
    """``{profile: tolerance}`` of buffer ``name`` of ``kind``, with a scene's ``overrides``
    (``{profile: {key: value}}``) applied."""
    out = {"exact": dict(_EXACT),
           "conformant": dict(CONFORMANT.get(name) or CONFORMANT_BY_KIND[kind])}
    for profile, changes in (overrides or {}).items():
        out[profile] = {**out.get(profile, _EXACT), **changes}
    for profile, tol in out.items():
        validate(tol, _TOLERANCE)
    return out


def parse_override(text):
    """Parse ``[SCENE:][BUFFER.]KEY=VALUE`` → ``(scene or None, buffer or None, key, value)``.

    ``VALUE`` is a number, or ``none`` to remove an optional limit.
    """
    if not isinstance(text, str) or "=" not in text:
        raise ValueError(f"tolerance override must look like [SCENE:][BUFFER.]KEY=VALUE, "
                         f"got {text!r}")
    lhs, value_text = text.split("=", 1)
    scene = None
    if ":" in lhs:
        scene, lhs = lhs.split(":", 1)
    buffer, key = lhs.rsplit(".", 1) if "." in lhs else (None, lhs)
    if key not in TOLERANCE_KEYS:
        raise ValueError(f"unknown tolerance key {key!r} in {text!r}; known: {TOLERANCE_KEYS}")
    value_text = value_text.strip()
    if value_text.lower() == "none":
        value = None
    else:
        try:
            value = int(value_text) if key == "deviation_radius" else float(value_text)
        except ValueError:
            raise ValueError(f"tolerance {key} needs a number, got {value_text!r}") from None
    return scene or None, buffer or None, key, value


def apply_overrides(tolerance, scene, buffer, overrides):
    """``tolerance`` with the parsed ``overrides`` that match (scene, buffer) applied in order."""
    tol = dict(tolerance)
    for o_scene, o_buffer, key, value in overrides:
        if o_scene not in (None, scene) or o_buffer not in (None, buffer):
            continue
        if value is None and key in ("threshold", "slope", "max_fraction", "deviation_radius"):
            raise ValueError(f"tolerance {key} cannot be none")
        tol[key] = value
    try:
        validate(tol, _TOLERANCE)
    except SchemaError as exc:
        raise ValueError(f"tolerance of {scene}/{buffer} after overrides: {exc}") from None
    return tol
