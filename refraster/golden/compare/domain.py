"""Domain checks: values no conformant backend can produce, refused in every compare mode.

A tolerance says how far a candidate may be from the golden; a domain check says what a value of
a buffer's kind can be at all, whatever the golden holds. They run before any allowance is
applied, so an allowance can never forgive garbage (a "may" pixel whose depth interval is
[0, 1] still refuses a NaN, a depth of 7 or an id of −7).

==================  ===========================================================================
check               fails where
==================  ===========================================================================
``nan``             any buffer holds NaN
``inf``             a float buffer is ±inf where the golden is finite — unless the candidate's own
                    ``prim_id`` says background there or (tolerant mode) coverage "may" differ;
                    −inf wherever the golden is not −inf
``depth_range``     a window-depth buffer (kind ``unorm``, name ending in ``depth``) leaves [0, 1]
``normal_length``   a covered normal's length is off 1 by more than 1e-3 + √3·step, or a
                    background normal has a component beyond one step (``step`` = the
                    candidate encoding's quantisation step; covered/background from the
                    candidate's own ``prim_id`` when it sends one, else whichever fits)
``id_range``        an id below −1 or above the largest id the scene can produce (the manifest's
                    ``ids`` range of the buffer, see docs/golden.md, "Id conventions")
``id_coverage``     ``object_id`` says covered where the candidate's ``prim_id`` says background,
                    or the other way round
``bool_values``     a bool buffer sent as integers holds anything but 0 and 1
==================  ===========================================================================

Each failing check names the first offending pixel (row-major) and its value, and how many
pixels fail.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["domain_checks", "NORMAL_LENGTH_TOL"]

#: Slack of a covered normal's length before the encoding's quantisation is added.
NORMAL_LENGTH_TOL = 1e-3


def _first(bad, values):
    """``(n, row, col, value)`` of the first pixel (row-major) of the (H, W) mask ``bad``."""
    n = int(bad.sum())
    flat = int(np.argmax(bad.reshape(-1)))
    r, c = divmod(flat, bad.shape[1])
    v = np.asarray(values)[r, c]
    return n, r, c, v.tolist() if isinstance(v, np.ndarray) else v.item()


def _fail(name, bad, values, what):
    n, r, c, v = _first(bad, values)
    return {"metric": f"domain:{name}", "value": n, "limit": 0, "op": "<=", "ok": False,
            "pixel": [r, c], "candidate_value": v,
            "detail": f"{what}; {n} pixel(s), first at row {r}, col {c}: {v!r}"}


def _pixels(mask):
    """Per-pixel (H, W) view of an (H, W) or (H, W, C) mask: any channel."""
    return mask.any(axis=2) if mask.ndim == 3 else mask


def domain_checks(key, kind, reference, candidate, *, step=0.0, raw=None, coverage=None,
                  may=None, id_range=None):
    """The failing domain checks of one candidate buffer (an empty list when it is in domain).

    Parameters
    ----------
    key, kind : str
        Buffer name and kind (:mod:`refraster.golden.io.buffers`).
    reference, candidate : arrays of the same shape
    step : float
        Quantisation step of the candidate's encoding (0 for exact files).
    raw : array, optional
        The candidate as sent, before a bool buffer's integers were turned into bools.
    coverage : (H, W) bool, optional
        The candidate's own coverage (its ``prim_id >= 0``), when it sends ids.
    may : (H, W) bool, optional
        Pixels whose coverage may differ from the golden's; used for ``inf`` when the
        candidate sends no ids (tolerant mode: the stored "may" region; otherwise the
        golden's covered pixels next to its background).
    id_range : (int, int), optional
        Smallest and largest id the scene can produce (default: −1 and no upper bound).

    Returns
    -------
    list of dict
        Check records as :func:`refraster.golden.compare.metrics.buffer_metrics` makes them,
        each with ``ok = False``, the first offending ``pixel`` and a ``detail`` sentence.
    """
    out = []
    c = np.asarray(candidate)
    if kind == "bool":
        r = np.asarray(raw) if raw is not None else c
        if r.dtype != np.bool_:
            bad = _pixels((r != 0) & (r != 1))
            if bad.any():
                out.append(_fail("bool_values", bad, r, "a bool buffer holds a value other "
                                 "than 0 and 1"))
        return out
    if kind == "id":
        lo, hi = id_range if id_range is not None else (-1, None)
        bad = _pixels(c < lo) | (_pixels(c > hi) if hi is not None else False)
        if np.any(bad):
            span = f"[{lo}, {hi}]" if hi is not None else f"≥ {lo}"
            out.append(_fail("id_range", np.asarray(bad), c,
                             f"an id outside what the scene can produce {span}"))
        if key == "object_id" and coverage is not None and c.ndim == 2:
            bad = (c >= 0) != np.asarray(coverage, np.bool_)
            if bad.any():
                out.append(_fail("id_coverage", bad, c, "object_id and prim_id disagree on "
                                 "whether the pixel is covered"))
        return out
    x = c.astype(np.float64, copy=False)
    nan = _pixels(np.isnan(x))
    if nan.any():
        out.append(_fail("nan", nan, c, "NaN"))
    ref = np.asarray(reference, np.float64)
    inf = np.isinf(x) & ~(x == ref)
    neg = _pixels(inf & (x < 0))
    pos = _pixels(inf & (x > 0))
    if coverage is not None:
        pos &= np.asarray(coverage, np.bool_)
    elif may is not None:
        pos &= ~np.asarray(may, np.bool_)
    if (neg | pos).any():
        out.append(_fail("inf", neg | pos, c, "±inf where the golden is finite (and the "
                         "candidate does not say background there)"))
    if kind == "unorm" and key.endswith("depth"):
        with np.errstate(invalid="ignore"):
            bad = _pixels((x < 0.0) | (x > 1.0))
        if bad.any():
            out.append(_fail("depth_range", bad, c, "window depth outside [0, 1]"))
    if kind == "snorm" and key.endswith("normal") and x.ndim == 3 and x.shape[2] == 3:
        with np.errstate(invalid="ignore", over="ignore"):
            length = np.sqrt(np.einsum("hwc,hwc->hw", x, x))
            unit = np.abs(length - 1.0) <= NORMAL_LENGTH_TOL + math.sqrt(3.0) * step
            zero = np.abs(x).max(axis=2) <= max(step, 0.0)
        if coverage is None:
            bad = ~(unit | zero) & ~nan
            what = "a normal that is neither unit length nor zero (background)"
        else:
            cov = np.asarray(coverage, np.bool_)
            bad = np.where(cov, ~unit, ~zero) & ~nan
            what = ("a covered normal not of unit length, or a background normal not zero "
                    "(coverage from the candidate's prim_id)")
        if bad.any():
            out.append(_fail("normal_length", bad, c, what + f" (step {step:.3g})"))
    return out
