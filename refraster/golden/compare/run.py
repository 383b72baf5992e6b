"""``golden compare``: check a candidate backend's buffers against a golden directory.

A candidate directory holds, per scene, either ``<scene>/buffers.npz`` (keys = buffer names,
the golden's own layout, so a golden compares against itself) or one file per buffer:
``<scene>/<buffer>.npy`` or ``<scene>/<buffer>.png`` (PNG encodings in
:mod:`refraster.golden.io.buffers`). Per scene and buffer the compare reports the largest error,
RMSE, PSNR, the fraction of pixels over the threshold, the fraction left after the
position-deviation compare, and mean FLIP for colour; it checks them against the buffer's
tolerance (:mod:`refraster.golden.compare.profiles`).

Nothing in the golden or candidate directory is ever written, moved or deleted.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.buffers import peak, png_decode  # noqa: F401  (old names importable from here)
from ..io.errors import EXIT_FAIL, EXIT_PASS, EXIT_UNUSABLE, CandidateError, GoldenError
from .domain import domain_checks
from .metrics import (_elementwise_error, _flip, _offsets, buffer_metrics, local_variation,  # noqa: F401
                      pixel_error, position_deviation)
from ..io.read import (_check_candidate, _inside, _manifest_paths, load_candidate,  # noqa: F401
                   load_manifest)
from ..io.read import allowance_arrays as _read_allowances
from ..io.read import reference_buffers as _read_reference
from ..io.read import some_names as _some_names
from .profiles import PROFILES, apply_overrides, parse_override

__all__ = ["GoldenError", "CandidateError", "BufferResult", "SceneResult", "Comparison",
           "compare", "load_manifest", "load_candidate", "pixel_error", "position_deviation",
           "local_variation",
           "buffer_metrics", "EXIT_PASS", "EXIT_FAIL", "EXIT_UNUSABLE", "MODES", "has_allowances",
           "buffer_allowance"]

# The golden and the candidate are read by :mod:`refraster.golden.io.read` (no links followed,
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


# --- metrics: in refraster.golden.compare.metrics (imported above under their old names) ----------


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
    #: tolerant mode: the per-pixel allowance arrays this buffer's checks used
    #: (:func:`buffer_allowance`), for the report's pixel read-out; ``None`` otherwise
    allowance: dict | None = field(default=None, repr=False)

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


def _unforgiven(b):
    """(H, W) bool: the pixels of a buffer result outside its allowance, or None."""
    over, forgiven = b.images.get("over"), b.images.get("forgiven")
    if over is None or forgiven is None:
        return None
    return np.asarray(over, np.bool_) & ~np.asarray(forgiven, np.bool_)


def _summary_line(b, tolerant):
    """One buffer's summary line (see :meth:`Comparison.summary`)."""
    m = b.metrics
    head = f"  {b.name:<14} {'ok  ' if b.passed else 'FAIL'}"
    err = b.images.get("error") if b.images else None
    if math.isfinite(m["max_abs"]) or err is None:
        head += f" max_abs={m['max_abs']:.3g} rmse={m['rmse']:.3g} psnr={m['psnr']:.1f}"
    else:   # a pixel covered in one and background (±inf) in the other
        e = np.asarray(err, np.float64)
        finite = np.isfinite(e)
        head += (f" max_abs={float(e[finite].max()) if finite.any() else 0.0:.3g} where both "
                 f"cover, {int((~finite).sum())} px covered in one only")
    flip = f" flip={m['flip_mean']:.4f}" if m.get("flip_mean") is not None else ""
    n, px, bad = m["n_over"], m["pixels"], m["n_unforgiven"]
    differ = (f" differing={n}/{px}" if tolerant else
              f" differing_by_more_than_{m['threshold']:.3g}={n}/{px}")
    if not b.passed:
        return head + differ + f" outside={bad}" + flip
    if n == 0:
        return head + differ + flip
    if tolerant or bad == 0:
        return head + differ + " (all admitted by the allowance)" + flip
    return (head + differ + f" (admitted: {n - bad} by position deviation, {bad} within "
            f"max_fraction {b.tolerance.get('max_fraction', 0):.3g})" + flip)


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
        """One line per failing check or unusable scene: ``scene/buffer: metric value op limit``.

        Ordered by cause within a scene: the id buffers first (a pixel whose ``prim_id`` names a
        face that cannot win there makes every value buffer wrong at that pixel too), then the
        other buffers, each marked with how many of its failing pixels follow from the ids'."""
        lines = []
        for s in self.scenes:
            if s.status == "error":
                lines.append(f"{s.name}: unusable candidate: {s.error}")
            id_bad = None
            for b in s.buffers:
                if b.kind == "id" and not b.passed:
                    m = _unforgiven(b)
                    if m is not None:
                        id_bad = m if id_bad is None else id_bad | m
            ids_first = sorted(s.buffers, key=lambda b: (b.kind != "id", b.name != "prim_id"))
            for b in ids_first:
                follows = ""
                if b.kind != "id" and id_bad is not None and not b.passed:
                    m = _unforgiven(b)
                    if m is not None and m.shape == id_bad.shape and m.any():
                        k, n = int((m & id_bad).sum()), int(m.sum())
                        follows = ("" if k == 0 else
                                   " [follows from the ids: every failing pixel is one where the "
                                   "candidate's ids fail]" if k == n else
                                   f" [{k} of its {n} failing pixels are where the ids fail]")
                for c in b.checks:
                    if c["ok"]:
                        continue
                    if c["metric"].startswith("domain:"):
                        line = f"{s.name}/{b.name}: {c['metric']}: {c['detail']}"
                    elif "detail" in c:
                        why = (" (the candidate's id names a face that cannot win here)"
                               if b.kind == "id" and c["metric"] in ("face", "id") else "")
                        line = (f"{s.name}/{b.name}: {c['metric']} = {c['value']} > "
                                f"{c['limit']}{why} ({c['detail']}; worst {b.metrics['worst']})")
                    else:
                        bad = ">" if c["op"] == "<=" else "<"
                        line = (f"{s.name}/{b.name}: {c['metric']} = {c['value']:.6g} "
                                f"{bad} {c['limit']:.6g} ({b.metrics['n_over']} of "
                                f"{b.metrics['pixels']} pixels over threshold "
                                f"{b.metrics['threshold']:.3g}; worst "
                                f"{b.metrics['worst']})")
                    lines.append(line + follows)
        return lines

    def summary(self):
        """A plain-text table: one line per scene and buffer.

        ``differing`` counts the pixels whose value differs from the golden's (tolerant mode)
        or differs by more than the profile's threshold (profile mode); ``outside`` counts those
        the allowance does not admit — a buffer passes when ``outside`` is 0 (tolerant) or
        within the profile's ``max_fraction``. A passing line says what admitted its
        differences and shows no count that reads as a failure."""
        tolerant = self.mode == "tolerant"
        how = "mode tolerant" if tolerant else f"profile {self.profile}"
        lines = [f"golden {self.golden_dir} vs candidate {self.candidate_dir} ({how})"]
        for s in self.scenes:
            lines.append(f"{s.name}: {s.status.upper()}" + (f" ({s.error})" if s.error else ""))
            if s.skipped:
                lines.append(f"  skipped (not in the golden, not read): "
                             f"{_some_names(s.skipped)}")
            for b in s.buffers:
                lines.append(_summary_line(b, tolerant))
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


def _check_nothing_compared(manifest, names, scenes, buffers):
    """A compare that would compare nothing is refused: it must never report a pass."""
    if not names:
        raise GoldenError("nothing to compare: " + ("no scene was selected" if scenes is not None
                                                    else "the golden has no scenes"))
    empty = [n for n in names if not manifest["scenes"][n]["buffers"]]
    if empty:
        how = ("every buffer was filtered out by the buffer selection" if buffers is not None
               else "the golden stores no buffers for them")
        raise GoldenError(f"nothing to compare for scene(s) {empty}: {how}")


def _candidate_coverage(cand, specs):
    """The candidate's own coverage (its ``prim_id >= 0``) when it sends a usable prim_id."""
    if "prim_id" not in cand or specs["prim_id"]["kind"] != "id":
        return None
    a = cand["prim_id"][0]
    return a >= 0 if a.ndim == 2 else None


def _edge_may(ref, specs):
    """Without ids or stored allowances: the golden's covered pixels next to its background
    (where a conformant candidate may show background instead)."""
    if "prim_id" in ref and specs.get("prim_id", {}).get("kind") == "id" \
            and np.asarray(ref["prim_id"]).ndim == 2:
        background = np.asarray(ref["prim_id"]) < 0
    elif "eye_depth" in ref and np.asarray(ref["eye_depth"]).ndim == 2:
        background = ~np.isfinite(np.asarray(ref["eye_depth"], np.float64))
    else:
        return None
    near = background.copy()
    for dst, src in _offsets(*background.shape, 1):
        near[dst] |= background[src]
    return near


def buffer_allowance(spec, arrays, *, step=0.0, clear_depth=1.0, depth_func="less"):
    """The allowance one buffer's tolerant checks use, as the report shows it per pixel.

    Parameters
    ----------
    spec : dict
        The buffer's ``"tolerant"`` manifest entry.
    arrays : dict
        The scene's ``tolerance.npz`` (:mod:`refraster.golden.allowances.core`).
    step, clear_depth : float
        As passed to :func:`refraster.golden.allowances.core.tolerant_metrics`.
    depth_func : str
        The scene's depth test (the direction of a depth buffer's coverage).

    Returns
    -------
    dict
        ``checks``, ``step``, ``clear_depth`` and the arrays (not copied) the checks read:
        ``id_may``, and where they apply ``coverage``, ``lo``/``hi``, ``angle``, ``may``.
    """
    out = {"checks": list(spec["checks"]), "step": float(step),
           "clear_depth": float(clear_depth), "depth_func": str(depth_func),
           "id_may": arrays["id_may"]}
    for key in ("lo", "hi", "angle", "zero"):
        if key in spec:
            out[key] = arrays[spec[key]]
    if "coverage" in spec["checks"]:
        out["coverage"] = arrays["coverage"]
    if "masked" in spec["checks"]:
        out["may"] = arrays[spec.get("may", "may")]
    return out


def _sample_view(allow, cand, s):
    """What the checks of a multisampled golden's buffers at sample ``s`` read: that sample's
    allowance arrays (``s<s>_<name>`` as ``<name>``), the candidate's buffers of that sample
    (``sample<s>_<channel>`` as ``<channel>``), the face-set entries its ids name and its
    coverage (:mod:`refraster.golden.allowances.samples`)."""
    p, q = f"s{s}_", f"sample{s}_"
    arrays = {k[len(p):]: v for k, v in allow.items() if k.startswith(p)}
    others = {k[len(q):]: v[0] for k, v in cand.items() if k.startswith(q)}
    named = coverage = None
    prim = others.get("prim_id")
    if prim is not None and np.asarray(prim).ndim == 2 \
            and np.issubdtype(np.asarray(prim).dtype, np.integer):
        from ..allowances.core import named_entries
        obj = others.get("object_id")
        named = named_entries(arrays, prim, obj if obj is not None and np.asarray(obj).ndim == 2
                              else None)
        coverage = np.asarray(prim) >= 0
    return arrays, others, named, coverage


def golden_sample_pattern(entry):
    """The sample pattern a golden scene declares (``parameters.technique.sample_pattern``:
    ``{"samples": S, "positions": [[x, y], ...]}``), or None for a single-sample scene."""
    return (entry.get("parameters", {}).get("technique") or {}).get("sample_pattern")


def _pattern_text(p):
    return (f"{p['samples']} samples at " + " ".join(f"({x}, {y})" for x, y in p["positions"]))


def check_sample_pattern(candidate_dir, name, entry):
    """A multisampled golden's candidate must state its own sample pattern in
    ``<scene>/sample_pattern.json`` (``{"samples": S, "positions": [[x, y], ...]}``, 1/16 pixel,
    y down from the pixel's upper-left corner as the picture is seen), and it must be the
    golden's: otherwise one :class:`CandidateError` line (the scene is unusable, exit 2)."""
    want = golden_sample_pattern(entry)
    if want is None:
        return
    from ..io.safe import read_json_file
    from ..io.read import PATTERN_FILE
    path = Path(candidate_dir) / name / PATTERN_FILE
    if not path.exists() and not path.is_symlink():
        raise CandidateError(f"the golden declares {_pattern_text(want)} (1/16 pixel, y down); "
                             f"the candidate states no sample pattern (write {name}/"
                             f"{PATTERN_FILE})")
    doc, _ = read_json_file(path, CandidateError, "candidate sample pattern", limit=1 << 16)
    try:
        got = {"samples": int(doc["samples"]),
               "positions": [[int(x), int(y)] for x, y in doc["positions"]]}
        if isinstance(doc["samples"], bool) or len(got["positions"]) != got["samples"]:
            raise ValueError
    except (KeyError, TypeError, ValueError):
        raise CandidateError(f"candidate {name}/{PATTERN_FILE} must hold {{\"samples\": S, "
                             f"\"positions\": [[x, y], ...]}} with S pairs of integers") from None
    if got != {"samples": int(want["samples"]), "positions": [list(p) for p in
                                                             want["positions"]]}:
        raise CandidateError(f"sample pattern mismatch: the golden declares "
                             f"{_pattern_text(want)}, the candidate states {_pattern_text(got)} "
                             "(1/16 pixel, y down); compare it against a golden of its pattern")


def has_allowances(manifest, names):
    """Whether every scene in ``names`` has stored allowances (a tolerant compare is possible)."""
    return all("allowances" in manifest["scenes"][n] for n in names)


def compare(golden_dir, candidate_dir, *, report=None, profile=None, tolerances=(),
            scenes=None, mode=None, buffers=None, outputs=None):
    """Compare a candidate directory against a golden directory.

    Parameters
    ----------
    golden_dir, candidate_dir : path
    report : path, optional
        Write an HTML report there (:func:`refraster.golden.compare.report.write_report`).
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
        (:mod:`refraster.golden.allowances.core`); buffers without an interval use the
        ``conformant`` profile with the "may" pixels forgiven. ``"exact"``: bit-exact. Default
        (neither ``mode`` nor ``profile``): ``"exact"``, so that code written for the
        profiles keeps its meaning; the command line defaults to tolerant
        (:mod:`refraster.golden.cli`).
    buffers : sequence of str, optional
        Compare only these buffers (default: all of each scene).
    outputs : refraster.golden.io.write.Outputs, optional
        Stage the report there instead of committing it now (the command line commits it
        together with ``--json``).

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
    from ..io.write import pending_swap
    pending_swap(golden_dir)  # a swap a killed generate left half-done: only generate acts
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
    _check_nothing_compared(manifest, names, scenes, buffers)
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
            check_sample_pattern(candidate_dir, name, entry)
            cand = load_candidate(candidate_dir, name, entry["buffers"], skipped)
        except CandidateError as exc:
            results.append(SceneResult(name, "error", [], str(exc), skipped=skipped))
            continue
        buffers = []
        coverage = _candidate_coverage(cand, entry["buffers"])
        named = None
        if allow is not None and coverage is not None:
            from ..allowances.core import named_entries
            obj = cand["object_id"][0] if "object_id" in cand else None
            named = named_entries(allow, cand["prim_id"][0],
                                  obj if obj is not None and obj.ndim == 2 else None)
        edge_may = (allow.get("may") if allow is not None
                    else _edge_may(ref, entry["buffers"]) if coverage is None else None)
        views = {}
        for key, spec in entry["buffers"].items():
            tol = spec["tolerance"].get(profile)
            if tol is None:
                raise GoldenError(f"the manifest has no {profile!r} tolerance for {name}/{key}")
            try:
                tol = apply_overrides(tol, name, key, overrides)
            except ValueError as exc:
                raise GoldenError(str(exc)) from None
            a, source, step, raw = cand[key]
            sample = spec.get("tolerant", {}).get("sample") if allow is not None else None
            if sample is not None:
                if sample not in views:
                    views[sample] = _sample_view(allow, cand, sample)
                arrays, others, b_named, b_coverage = views[sample]
                b_may = arrays.get("may")
                # the checks dispatch on the channel's own name (depth, prim_id, ...)
                channel = key[len(f"sample{sample}_"):]
            else:
                channel = key
                arrays, others, b_named, b_coverage = (
                    allow, {k: v[0] for k, v in cand.items()}, named, coverage)
                b_may = edge_may
            if allow is not None:
                from ..allowances.core import tolerant_metrics
                clear = entry["parameters"]["raster"].get("clear_depth", 1.0)
                func = entry["parameters"]["raster"].get("depth_func", "less")
                metrics, checks, images = tolerant_metrics(
                    channel, ref[key], a, spec["kind"], spec["tolerant"], arrays,
                    clear_depth=clear,
                    depth_func=func,
                    fallback=tol, step=step, named=b_named, others=others)
                if spec["kind"] == "color" and metrics.get("flip_mean") is None:
                    # information only: in tolerant mode the allowance, not FLIP, decides
                    try:
                        metrics["flip_mean"], images["flip"] = _flip(ref[key], a)
                    except ImportError:
                        metrics["flip_mean"] = None
                tol = {**tol, "tolerant": spec["tolerant"]}
                allowance = buffer_allowance(spec["tolerant"], arrays, step=step,
                                             clear_depth=clear, depth_func=func)
                if "face" in spec["tolerant"]["checks"]:
                    allowance.update(sets=arrays, named=b_named)
            else:
                metrics, checks, images = buffer_metrics(ref[key], a, spec["kind"], tol,
                                                         step=step)
                allowance = None
            checks = checks + domain_checks(
                key, spec["kind"], ref[key], a, step=step, raw=raw, coverage=b_coverage,
                may=b_may, id_range=spec.get("ids"))
            buffers.append(BufferResult(key, spec["kind"], source, tol, metrics, checks,
                                        ref[key], a, images, allowance))
        status = "pass" if all(b.passed for b in buffers) else "fail"
        results.append(SceneResult(name, status, buffers, skipped=skipped))
    comparison = Comparison(golden_dir, candidate_dir, "tolerant" if mode == "tolerant"
                            else profile, results, mode="tolerant" if mode == "tolerant"
                            else "profile")
    if report is not None:
        from .report import write_report
        comparison.report_dir = write_report(report, comparison, manifest, outputs=outputs)
    return comparison
