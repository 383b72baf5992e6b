"""The candidate's declared sub-pixel precision, which every allowance that depends on vertex
snapping reads (``golden generate --candidate-subpixel-bits``, docs/tolerance.md).

A candidate snaps window positions to ``2^−b`` pixel; the allowances bound what that does (the
edge ε of :func:`refraster.conformance.edge_epsilon`, the snappings the barycentric bounds
enumerate, the halos' sample shift). ``b`` is declared when the golden is generated — 8 by
default, as the CTS reference renderer and current desktop GPUs; 4, OpenGL's minimum, for the
devices that use it — and recorded in the manifest (``candidate.subpixel_bits`` and each scene's
``allowances.min_subpixel_bits``). A manifest without the field was generated for 4 bits.

Scene functions that derive a decision region while they build the scene (the clip surfaces'
and the sprite's ``GoldenScene.may``) read the declared value with :func:`candidate_bits`;
:func:`refraster.golden.generate.render_task` declares it around the build with
:func:`declared`.
"""

from __future__ import annotations

import contextlib
import contextvars

import numpy as np

__all__ = ["CANDIDATE_BITS", "LEGACY_CANDIDATE_BITS", "MIN_CANDIDATE_BITS", "MAX_CANDIDATE_BITS",
           "as_candidate_bits", "candidate_bits", "declared", "manifest_candidate_bits"]

#: The default declaration: 8 sub-pixel bits.
CANDIDATE_BITS = 8
#: What a golden whose manifest does not record the declaration was generated for.
LEGACY_CANDIDATE_BITS = 4
#: The allowed declarations: OpenGL's minimum (4) to the reference's own precision (8).
MIN_CANDIDATE_BITS, MAX_CANDIDATE_BITS = 4, 8

_BITS = contextvars.ContextVar("refraster_candidate_subpixel_bits", default=CANDIDATE_BITS)


def as_candidate_bits(value, name="candidate_subpixel_bits"):
    """``value`` as an int from 4 to 8, or one clear ValueError/TypeError naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int from {MIN_CANDIDATE_BITS} to "
                        f"{MAX_CANDIDATE_BITS}, got {type(value).__name__} {value!r}")
    value = int(value)
    if not MIN_CANDIDATE_BITS <= value <= MAX_CANDIDATE_BITS:
        raise ValueError(f"{name} must be from {MIN_CANDIDATE_BITS} to {MAX_CANDIDATE_BITS} "
                         f"(the sub-pixel bits a conformant candidate may use), got {value}")
    return value


def candidate_bits():
    """The declared sub-pixel bits of the candidate (8 unless inside :func:`declared`)."""
    return _BITS.get()


@contextlib.contextmanager
def declared(bits):
    """Declare the candidate's sub-pixel bits for the scene functions called inside."""
    token = _BITS.set(as_candidate_bits(bits))
    try:
        yield
    finally:
        _BITS.reset(token)


def manifest_candidate_bits(manifest):
    """The bits a golden's allowances were derived for: its manifest's
    ``candidate.subpixel_bits``, or 4 for a golden written before the field existed."""
    cand = manifest.get("candidate")
    if isinstance(cand, dict) and "subpixel_bits" in cand:
        return int(cand["subpixel_bits"])
    return LEGACY_CANDIDATE_BITS
