"""Per-buffer metrics of a comparison: per-pixel error, local variation, the position-deviation
compare, FLIP and the pass/fail checks of one buffer against a tolerance.

Used by :mod:`refraster.golden.compare.run` (profile compare) and
:mod:`refraster.golden.allowances.core` (the tolerant compare's fallback); it imports neither, so
neither imports the other.
"""

from __future__ import annotations

import math

import numpy as np

from ..io.buffers import peak
from ..io.errors import GoldenError

__all__ = ["pixel_error", "local_variation", "position_deviation", "buffer_metrics",
           "elementwise_error"]


def _elementwise_error(reference, candidate):
    r = np.asarray(reference, np.float64)
    c = np.asarray(candidate, np.float64)
    with np.errstate(invalid="ignore"):
        e = np.abs(r - c)
    e[r == c] = 0.0  # equal infinities (eye-depth background) agree
    e[np.isnan(e)] = np.inf
    return e


def pixel_error(reference, candidate):
    """Per-pixel error ``(H, W)``: the largest ``|ref − cand|`` over channels; equal
    infinities count as 0, NaN and unequal infinities as ``inf``."""
    e = _elementwise_error(reference, candidate)
    return e.max(axis=2) if e.ndim == 3 else e


def _offsets(h, w, radius):
    """(destination, source) slice pairs that move an (H, W) image by every (dy, dx) with
    ``max(|dy|, |dx|) <= radius``, (0, 0) excluded."""
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dy or dx:
                yield ((slice(max(-dy, 0), h + min(-dy, 0)), slice(max(-dx, 0), w + min(-dx, 0))),
                       (slice(max(dy, 0), h + min(dy, 0)), slice(max(dx, 0), w + min(dx, 0))))


def local_variation(reference):
    """(H, W): the largest difference between a pixel and its 8 neighbours (max over channels;
    pairs with a non-finite value are skipped). Multiplied by ``slope`` it is the change a shift
    of ``slope`` pixels makes — what another sub-pixel precision does to interpolated values."""
    r = np.asarray(reference, np.float64)
    h, w = r.shape[:2]
    out = np.zeros((h, w))
    for dst, src in _offsets(h, w, 1):
        with np.errstate(invalid="ignore"):
            d = np.abs(r[dst] - r[src])
        if d.ndim == 3:
            d = d.max(axis=2)
        out[dst] = np.maximum(out[dst], np.where(np.isfinite(d), d, 0.0))
    return out


def _matched_within(a, b, threshold, radius):
    """(H, W) bool: some pixel of ``b`` within ``radius`` (Chebyshev) of p matches ``a[p]``
    (error ≤ ``threshold[p]``)."""
    matched = pixel_error(a, b) <= threshold
    for dst, src in _offsets(a.shape[0], a.shape[1], radius):
        matched[dst] |= pixel_error(a[dst], b[src]) <= threshold[dst]
    return matched


def position_deviation(reference, candidate, threshold, radius):
    """Pixels that pass the position-deviation compare.

    A pixel p passes when the candidate's value at p matches (error ≤ ``threshold``) the
    reference somewhere within ``radius`` pixels of p **and** the reference's value at p matches
    the candidate somewhere within ``radius`` pixels. The Khronos conformance tests
    (``tcu::intThresholdPositionDeviationCompare``) check the first direction only; the second
    one keeps a candidate from dropping a one-pixel-wide feature whose neighbours all look like
    background.

    Parameters
    ----------
    reference, candidate : (H, W) or (H, W, C) arrays
    threshold : float or (H, W) float
    radius : int >= 0

    Returns
    -------
    (H, W) bool
    """
    thr = np.broadcast_to(np.asarray(threshold, np.float64), np.shape(reference)[:2])
    return (_matched_within(candidate, reference, thr, radius)
            & _matched_within(reference, candidate, thr, radius))


def _flip(reference, candidate):
    import flip_evaluator
    ref = np.ascontiguousarray(np.clip(reference, 0.0, 1.0), np.float32)
    cand = np.ascontiguousarray(np.clip(np.nan_to_num(candidate, nan=0.0), 0.0, 1.0), np.float32)
    fmap, mean, _ = flip_evaluator.evaluate(ref, cand, "LDR", applyMagma=True)
    return float(mean), np.asarray(fmap)


def buffer_metrics(reference, candidate, kind, tolerance, *, step=0.0, forgive=None):
    """Metrics and pass/fail checks of one buffer.

    Parameters
    ----------
    reference, candidate : (H, W) or (H, W, C) arrays of the same shape
    kind : str
        Buffer kind (:mod:`refraster.golden.io.buffers`).
    tolerance : dict
        See :mod:`refraster.golden.compare.profiles`.
    step : float
        Quantisation step of the candidate's encoding; the threshold is raised to it.
    forgive : (H, W) bool, optional
        Pixels forgiven whatever their error (a tolerant golden's "may" region).

    Returns
    -------
    metrics : dict
        ``max_abs, rmse, psnr, threshold, fraction_over, n_over, fraction_unforgiven,
        n_unforgiven, worst`` and, for colour, ``flip_mean``.
    checks : list of dict
        ``{"metric", "value", "limit", "ok"}`` for each limit that applies.
    images : dict
        ``error`` (per-pixel), ``over`` and ``forgiven`` masks, ``flip`` map (colour).
    """
    err_el = _elementwise_error(reference, candidate)
    err = err_el.max(axis=2) if err_el.ndim == 3 else err_el
    threshold = max(float(tolerance["threshold"]), float(step))
    slope = float(tolerance.get("slope") or 0.0)
    thr = threshold + slope * local_variation(reference) if slope > 0 else np.full(err.shape,
                                                                                   threshold)
    over = err > thr
    radius = int(tolerance["deviation_radius"])
    forgiven = (position_deviation(reference, candidate, thr, radius) & over
                if radius > 0 and over.any() else np.zeros_like(over))
    if forgive is not None:
        forgiven |= over & np.asarray(forgive, np.bool_)
    unforgiven = over & ~forgiven
    mse = float(np.mean(err_el ** 2)) if err_el.size else 0.0
    p = peak(reference, kind)
    psnr = math.inf if mse == 0 else (-math.inf if not math.isfinite(mse)
                                      else 10.0 * math.log10(p * p / mse))
    n = err.size
    metrics = {"max_abs": float(err.max()) if n else 0.0, "rmse": math.sqrt(mse), "psnr": psnr,
               "threshold": threshold, "fraction_over": float(over.sum()) / n,
               "n_over": int(over.sum()), "fraction_unforgiven": float(unforgiven.sum()) / n,
               "n_unforgiven": int(unforgiven.sum()), "pixels": n, "worst": None}
    if unforgiven.any() or over.any():
        pick = unforgiven if unforgiven.any() else over
        flat = int(np.argmax(np.where(pick, err, -1.0)))
        r, c = divmod(flat, err.shape[1])
        metrics["worst"] = {"row": r, "col": c,
                            "reference": np.asarray(reference)[r, c].tolist(),
                            "candidate": np.asarray(candidate)[r, c].tolist()}
    images = {"error": err, "over": over, "forgiven": forgiven, "flip": None}
    checks = []
    if radius == 0 and forgive is None:
        checks.append(("fraction_over", metrics["fraction_over"], tolerance["max_fraction"],
                       "<="))
    else:
        checks.append(("position_deviation", metrics["fraction_unforgiven"],
                       tolerance["max_fraction"], "<="))
    if tolerance.get("max_abs") is not None:
        checks.append(("max_abs", metrics["max_abs"], tolerance["max_abs"], "<="))
    if tolerance.get("min_psnr") is not None:
        checks.append(("psnr", psnr, tolerance["min_psnr"], ">="))
    if kind == "color":
        try:
            metrics["flip_mean"], images["flip"] = _flip(reference, candidate)
        except ImportError:
            metrics["flip_mean"] = None
            if tolerance.get("max_flip_mean") is not None:
                raise GoldenError("the colour tolerance limits FLIP but the flip-evaluator "
                                  "package is not installed (pip install flip-evaluator)")
        if tolerance.get("max_flip_mean") is not None:
            checks.append(("flip", metrics["flip_mean"], tolerance["max_flip_mean"], "<="))
    checks = [{"metric": m, "value": v, "limit": lim, "op": op,
               "ok": bool(v <= lim if op == "<=" else v >= lim)} for m, v, lim, op in checks]
    return metrics, checks, images


#: public name of the element-wise error (the tolerant compare uses it)
elementwise_error = _elementwise_error
