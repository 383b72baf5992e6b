"""``golden compare``: check a candidate backend's buffers against a golden directory.

A candidate directory holds, per scene, either ``<scene>/buffers.npz`` (keys = buffer names,
the golden's own layout, so a golden compares against itself) or one file per buffer:
``<scene>/<buffer>.npy`` or ``<scene>/<buffer>.png`` (PNG encodings in
:mod:`refraster.golden.buffers`). Per scene and buffer the compare reports the largest error,
RMSE, PSNR, the fraction of pixels over the threshold, the fraction left after the
position-deviation compare, and mean FLIP for colour; it checks them against the buffer's
tolerance (:mod:`refraster.golden.tolerance`).

Nothing in the golden or candidate directory is ever written, moved or deleted.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .buffers import peak
from .read import (CandidateError, GoldenError, _check_candidate, _inside,  # noqa: F401
                   _manifest_paths, load_candidate, load_manifest)
from .read import allowance_arrays as _read_allowances
from .read import reference_buffers as _read_reference
from .tolerance import PROFILES, apply_overrides, parse_override

__all__ = ["GoldenError", "CandidateError", "BufferResult", "SceneResult", "Comparison",
           "compare", "load_manifest", "load_candidate", "pixel_error", "position_deviation",
           "local_variation",
           "buffer_metrics", "EXIT_PASS", "EXIT_FAIL", "EXIT_UNUSABLE", "MODES", "has_allowances"]

EXIT_PASS, EXIT_FAIL, EXIT_UNUSABLE = 0, 1, 2


# The golden and the candidate are read by :mod:`refraster.golden.read` (no links followed,
# headers first, scene packages validated); the old names stay importable from here.

def _reference(root, name, entry, manifest=None):
    """The golden buffers of scene ``name`` (``manifest``: the golden's, read if not given)."""
    manifest = load_manifest(root, verify=False) if manifest is None else manifest
    return _read_reference(root, {**manifest, "scenes": {**manifest["scenes"], name: entry}},
                           name)


def _allowance_arrays(root, name, entry, manifest=None):
    manifest = load_manifest(root, verify=False) if manifest is None else manifest
    return _read_allowances(root, {**manifest, "scenes": {**manifest["scenes"], name: entry}},
                            name)


# --- metrics -------------------------------------------------------------------------------------

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
        Buffer kind (:mod:`refraster.golden.buffers`).
    tolerance : dict
        See :mod:`refraster.golden.tolerance`.
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


# --- the comparison ------------------------------------------------------------------------------

@dataclass
class BufferResult:
    name: str
    kind: str
    source: str
    tolerance: dict
    metrics: dict
    checks: list
    reference: np.ndarray = field(repr=False)
    candidate: np.ndarray = field(repr=False)
    images: dict = field(repr=False)

    @property
    def passed(self):
        return all(c["ok"] for c in self.checks)

    @property
    def failed_metrics(self):
        return [c["metric"] for c in self.checks if not c["ok"]]


@dataclass
class SceneResult:
    name: str
    status: str  # "pass", "fail" or "error"
    buffers: list
    error: str | None = None
    preview_root: Path | None = None
    #: Candidate ``.npz`` members the golden does not have, skipped unread.
    skipped: list = field(default_factory=list)


@dataclass
class Comparison:
    golden_dir: Path
    candidate_dir: Path
    profile: str
    scenes: list
    report_dir: Path | None = None
    mode: str = "profile"

    @property
    def exit_code(self):
        statuses = {s.status for s in self.scenes}
        if "error" in statuses:
            return EXIT_UNUSABLE
        return EXIT_FAIL if "fail" in statuses else EXIT_PASS

    def failures(self):
        """One line per failing check or unusable scene: ``scene/buffer: metric value op limit``."""
        lines = []
        for s in self.scenes:
            if s.status == "error":
                lines.append(f"{s.name}: unusable candidate: {s.error}")
            for b in s.buffers:
                for c in b.checks:
                    if not c["ok"] and "detail" in c:
                        lines.append(f"{s.name}/{b.name}: {c['metric']} = {c['value']} > "
                                     f"{c['limit']} ({c['detail']}; worst {b.metrics['worst']})")
                    elif not c["ok"]:
                        bad = ">" if c["op"] == "<=" else "<"
                        lines.append(f"{s.name}/{b.name}: {c['metric']} = {c['value']:.6g} "
                                     f"{bad} {c['limit']:.6g} ({b.metrics['n_over']} of "
                                     f"{b.metrics['pixels']} pixels over threshold "
                                     f"{b.metrics['threshold']:.3g}; worst "
                                     f"{b.metrics['worst']})")
        return lines

    def summary(self):
        """A plain-text table: one line per scene and buffer."""
        how = "mode tolerant" if self.mode == "tolerant" else f"profile {self.profile}"
        lines = [f"golden {self.golden_dir} vs candidate {self.candidate_dir} ({how})"]
        for s in self.scenes:
            lines.append(f"{s.name}: {s.status.upper()}" + (f" ({s.error})" if s.error else ""))
            if s.skipped:
                lines.append(f"  skipped (not in the golden, not read): {', '.join(s.skipped)}")
            for b in s.buffers:
                m = b.metrics
                flip = (f" flip={m['flip_mean']:.4f}" if m.get("flip_mean") is not None else "")
                lines.append(
                    f"  {b.name:<14} {'ok  ' if b.passed else 'FAIL'} max_abs={m['max_abs']:.3g}"
                    f" rmse={m['rmse']:.3g} psnr={m['psnr']:.1f} over={m['fraction_over']:.2e}"
                    f" unforgiven={m['fraction_unforgiven']:.2e}{flip}")
        lines.append(f"result: {['PASS', 'FAIL', 'UNUSABLE INPUT'][self.exit_code]}")
        return "\n".join(lines)

    def to_json(self):
        def clean(x):
            if isinstance(x, float) and not math.isfinite(x):
                return str(x)
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, list):
                return [clean(v) for v in x]
            return x
        return clean({
            "golden_dir": str(self.golden_dir), "candidate_dir": str(self.candidate_dir),
            "profile": self.profile, "mode": self.mode, "exit_code": self.exit_code,
            "scenes": {s.name: {"status": s.status, "error": s.error, "buffers": {
                b.name: {"kind": b.kind, "source": b.source, "passed": b.passed,
                         "tolerance": b.tolerance, "metrics": b.metrics, "checks": b.checks}
                for b in s.buffers}} for s in self.scenes},
        })


def _check_overrides(overrides, manifest, names):
    for scene, buffer, _, _ in overrides:
        if scene is not None and scene not in names:
            raise GoldenError(f"tolerance override names scene {scene!r}, not compared; "
                              f"compared: {names}")
        if buffer is not None and not any(buffer in manifest["scenes"][n]["buffers"]
                                          for n in names if scene in (None, n)):
            raise GoldenError(f"tolerance override names buffer {buffer!r}, which no compared "
                              "scene has")


MODES = ("tolerant", "exact")


def has_allowances(manifest, names):
    """Whether every scene in ``names`` has stored allowances (a tolerant compare is possible)."""
    return all("allowances" in manifest["scenes"][n] for n in names)


def compare(golden_dir, candidate_dir, *, report=None, profile=None, tolerances=(),
            scenes=None, mode=None, buffers=None):
    """Compare a candidate directory against a golden directory.

    Parameters
    ----------
    golden_dir, candidate_dir : path
    report : path, optional
        Write an HTML report there (:func:`refraster.golden.report.write_report`).
    profile : str, optional
        Tolerance profile stored in the manifest: ``"exact"`` or ``"conformant"`` (the
        per-buffer metric thresholds). Given alone, it selects that profile's compare.
    tolerances : sequence of str
        Overrides ``[SCENE:][BUFFER.]KEY=VALUE`` applied after the profile, in order (in
        tolerant mode: to the buffers that fall back to the conformant profile).
    scenes : sequence of str, optional
        Compare only these scenes (default: all of the manifest).
    mode : {"tolerant", "exact"}, optional
        ``"tolerant"``: the stored coverage masks and value intervals
        (:mod:`refraster.golden.allowance`); buffers without an interval use the
        ``conformant`` profile with the "may" pixels forgiven. ``"exact"``: bit-exact. Default
        (neither ``mode`` nor ``profile``): ``"exact"``, so that code written for the
        profiles keeps its meaning; the command line defaults to tolerant
        (:mod:`refraster.golden.cli`).
    buffers : sequence of str, optional
        Compare only these buffers (default: all of each scene).

    Returns
    -------
    Comparison
        ``exit_code`` 0 pass, 1 fail, 2 a candidate scene is unusable.

    Raises
    ------
    GoldenError
        The golden directory, the arguments or the report directory are unusable.
    """
    golden_dir, candidate_dir = Path(golden_dir), Path(candidate_dir)
    if mode is not None and mode not in MODES:
        raise GoldenError(f"mode must be one of {MODES}, got {mode!r}")
    if profile is not None and profile not in PROFILES:
        raise GoldenError(f"profile must be one of {PROFILES}, got {profile!r}")
    if mode == "tolerant" and profile is not None:
        raise GoldenError("mode 'tolerant' uses the stored allowances (and the 'conformant' "
                          "profile where a buffer has none); do not also pass a profile")
    if mode == "exact" and profile not in (None, "exact"):
        raise GoldenError(f"mode 'exact' is the 'exact' profile; got profile {profile!r}")
    if mode is None:
        mode = "profile"
        profile = profile or "exact"
    elif mode == "exact":
        mode, profile = "profile", "exact"
    else:
        profile = "conformant"
    if not candidate_dir.is_dir():
        raise GoldenError(f"candidate directory {candidate_dir} does not exist")
    manifest = load_manifest(golden_dir)
    try:
        overrides = [parse_override(t) for t in tolerances]
    except ValueError as exc:
        raise GoldenError(str(exc)) from None
    names = list(manifest["scenes"]) if scenes is None else list(scenes)
    unknown = [n for n in names if n not in manifest["scenes"]]
    if unknown:
        raise GoldenError(f"scene(s) {unknown} are not in the golden; it has "
                          f"{sorted(manifest['scenes'])}")
    if mode == "tolerant" and not has_allowances(manifest, names):
        bare = [n for n in names if "allowances" not in manifest["scenes"][n]]
        raise GoldenError(f"scene(s) {bare} have no stored allowances (a golden written before "
                          "they existed); regenerate it or compare with --mode exact")
    if buffers is not None:
        buffers = list(buffers)
        for n in names:
            missing = [b for b in buffers if b not in manifest["scenes"][n]["buffers"]]
            if missing:
                raise GoldenError(f"scene {n!r} has no buffer(s) {missing}; it has "
                                  f"{sorted(manifest['scenes'][n]['buffers'])}")
        manifest = json.loads(json.dumps(manifest))
        for n in names:
            specs = manifest["scenes"][n]["buffers"]
            manifest["scenes"][n]["buffers"] = {k: specs[k] for k in specs if k in buffers}
    _check_overrides(overrides, manifest, names)
    if report is not None:
        from .report import check_report_dir
        check_report_dir(report, golden_dir, candidate_dir)
    results = []
    for name in names:
        entry = manifest["scenes"][name]
        ref = _reference(golden_dir, name, entry, manifest)
        allow = (_allowance_arrays(golden_dir, name, entry, manifest) if mode == "tolerant"
                 else None)
        skipped = []
        try:
            cand = load_candidate(candidate_dir, name, entry["buffers"], skipped)
        except CandidateError as exc:
            results.append(SceneResult(name, "error", [], str(exc), skipped=skipped))
            continue
        buffers = []
        for key, spec in entry["buffers"].items():
            tol = spec["tolerance"].get(profile)
            if tol is None:
                raise GoldenError(f"the manifest has no {profile!r} tolerance for {name}/{key}")
            try:
                tol = apply_overrides(tol, name, key, overrides)
            except ValueError as exc:
                raise GoldenError(str(exc)) from None
            a, source, step = cand[key]
            if allow is not None:
                from .allowance import tolerant_metrics
                clear = entry["parameters"]["raster"].get("clear_depth", 1.0)
                metrics, checks, images = tolerant_metrics(
                    key, ref[key], a, spec["kind"], spec["tolerant"], allow, clear_depth=clear,
                    fallback=tol, step=step)
                tol = {**tol, "tolerant": spec["tolerant"]}
            else:
                metrics, checks, images = buffer_metrics(ref[key], a, spec["kind"], tol,
                                                         step=step)
            buffers.append(BufferResult(key, spec["kind"], source, tol, metrics, checks,
                                        ref[key], a, images))
        status = "pass" if all(b.passed for b in buffers) else "fail"
        results.append(SceneResult(name, status, buffers, skipped=skipped))
    comparison = Comparison(golden_dir, candidate_dir, "tolerant" if mode == "tolerant"
                            else profile, results, mode="tolerant" if mode == "tolerant"
                            else "profile")
    if report is not None:
        from .report import write_report
        comparison.report_dir = write_report(report, comparison, manifest)
    return comparison
