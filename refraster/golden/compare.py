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
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .buffers import peak, png_decode
from .package import sha256_file
from .schema import (MANIFEST_SCHEMA, MANIFEST_SCHEMA_VERSION, SchemaError, check_version,
                     is_safe_relpath, validate)
from .tolerance import PROFILES, apply_overrides, parse_override

__all__ = ["GoldenError", "CandidateError", "BufferResult", "SceneResult", "Comparison",
           "compare", "load_manifest", "load_candidate", "pixel_error", "position_deviation",
           "local_variation",
           "buffer_metrics", "EXIT_PASS", "EXIT_FAIL", "EXIT_UNUSABLE", "MODES", "has_allowances",
           "buffer_allowance"]

EXIT_PASS, EXIT_FAIL, EXIT_UNUSABLE = 0, 1, 2


class GoldenError(ValueError):
    """The golden directory, the arguments or the report directory cannot be used."""


class CandidateError(ValueError):
    """A candidate scene's files are missing, unreadable or of the wrong shape or dtype."""


# --- the golden ----------------------------------------------------------------------------------

def _manifest_paths(manifest):
    """(JSON path, relative path) of every file the manifest points at."""
    scenes = manifest.get("scenes")
    for name, scene in (scenes.items() if isinstance(scenes, dict) else ()):
        if not isinstance(scene, dict):
            continue
        for key in ("package", "buffers_file"):
            if key in scene:
                yield f"$.scenes.{name}.{key}", scene[key]
        allowances = scene.get("allowances")
        if isinstance(allowances, dict) and "file" in allowances:
            yield f"$.scenes.{name}.allowances.file", allowances["file"]
        buffers = scene.get("buffers")
        for bname, buf in (buffers.items() if isinstance(buffers, dict) else ()):
            if isinstance(buf, dict) and "preview" in buf:
                yield f"$.scenes.{name}.buffers.{bname}.preview", buf["preview"]
    files = manifest.get("files")
    for rel in (files if isinstance(files, dict) else ()):
        yield "$.files", rel


def _inside(root, rel, where):
    """``root / rel`` resolved, refusing anything that leaves ``root`` (``..``, absolute paths,
    symlinks pointing out)."""
    if not is_safe_relpath(rel):
        raise GoldenError(f"{where}: path {rel!r} leaves the golden directory or is not a plain "
                          "relative path; refusing to read it")
    path = (root / rel).resolve()
    if not path.is_relative_to(root.resolve()):
        raise GoldenError(f"{where}: path {rel!r} resolves to {path}, outside the golden "
                          "directory; refusing to read it")
    return path


def load_manifest(golden_dir, *, verify=True):
    """Read, check and return ``golden_dir/manifest.json``.

    Raises :class:`GoldenError` for a missing or unparsable manifest, one of another kind or a
    newer schema version, a schema violation, a path leaving the directory, or (``verify``) a
    file whose sha256 differs from the manifest's.
    """
    root = Path(golden_dir)
    path = root / "manifest.json"
    if not path.is_file():
        raise GoldenError(f"{root} is not a golden directory: {path} not found")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise GoldenError(f"cannot read {path}: {exc}") from None
    try:
        check_version(manifest, kind="refraster.golden", supported=MANIFEST_SCHEMA_VERSION,
                      what=str(path))
        for where, rel in _manifest_paths(manifest):
            _inside(root, rel, f"{path} {where}")
        validate(manifest, MANIFEST_SCHEMA)
    except SchemaError as exc:
        raise GoldenError(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") \
            from None
    for where, rel in _manifest_paths(manifest):
        if rel not in manifest["files"]:
            raise GoldenError(f"{path} {where}: {rel!r} is not listed in $.files")
    if verify:
        for rel, digest in manifest["files"].items():
            file = _inside(root, rel, f"{path} $.files")
            if not file.is_file():
                raise GoldenError(f"golden file {file} is missing")
            if sha256_file(file) != digest:
                raise GoldenError(f"golden file {file} does not match its sha256 in the "
                                  "manifest (corrupt or edited)")
    return manifest


def _load_npz(path, error):
    try:
        # np.load leaks its own handle when the zip is corrupt; own the file instead
        with open(path, "rb") as fh:
            z = np.load(fh, allow_pickle=False)
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise ValueError("not an .npz archive")
            with z:
                return {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as exc:
        raise error(f"cannot read {path}: {type(exc).__name__}: {exc}") from None


def _allowance_arrays(root, name, entry):
    spec = entry["allowances"]
    arrays = _load_npz(_inside(root, spec["file"], name), GoldenError)
    _check_arrays(arrays, spec["arrays"], spec["file"], "array")
    for key, b in entry["buffers"].items():
        t = b.get("tolerant", {})
        needed = [t[k] for k in ("lo", "hi", "angle", "may") if k in t]
        needed += ["id_may"] + (["coverage"] if "coverage" in t.get("checks", ()) else [])
        missing = [n for n in needed if n not in arrays]
        if missing:
            raise GoldenError(f"golden {spec['file']}: buffer {key!r} needs arrays {missing}")
    return arrays


def _reference(root, name, entry):
    arrays = _load_npz(_inside(root, entry["buffers_file"], name), GoldenError)
    _check_arrays(arrays, entry["buffers"], entry["buffers_file"], "buffer")
    return arrays


def _check_arrays(arrays, specs, file, kind):
    """Every array the manifest lists is in ``arrays`` with its dtype and shape."""
    for key, spec in specs.items():
        a = arrays.get(key)
        if a is None or list(a.shape) != spec["shape"] or str(a.dtype) != spec["dtype"]:
            raise GoldenError(f"golden {file}: {kind} {key!r} does not match the manifest "
                              f"({spec['dtype']} {spec['shape']})")


# --- the candidate -------------------------------------------------------------------------------

_FLOAT_KINDS = ("unorm", "snorm", "float", "color")


def _check_candidate(scene, key, spec, a, source):
    shape = tuple(spec["shape"])
    kind = spec["kind"]
    where = f"candidate {source} ({scene}/{key})"
    if a.dtype == object:
        raise CandidateError(f"{where}: object arrays are not accepted")
    if a.shape != shape:
        raise CandidateError(f"{where}: shape {a.shape} differs from the golden's {shape}")
    if kind in _FLOAT_KINDS and not np.issubdtype(a.dtype, np.floating):
        raise CandidateError(f"{where}: expected floating-point values ({kind}), got {a.dtype}")
    if kind == "id" and not np.issubdtype(a.dtype, np.integer):
        raise CandidateError(f"{where}: expected integer ids, got {a.dtype}")
    if kind == "bool":
        if np.issubdtype(a.dtype, np.integer) and np.isin(a, (0, 1)).all():
            a = a.astype(bool)
        elif a.dtype != np.bool_:
            raise CandidateError(f"{where}: expected bool (or integer 0/1), got {a.dtype}")
    return a


def load_candidate(candidate_dir, scene, specs):
    """Candidate buffers of ``scene``: ``{key: (array, source, step)}``; ``step`` is the PNG
    quantisation step (0 for exact files). Raises :class:`CandidateError`."""
    import imageio.v3 as iio
    base = Path(candidate_dir) / scene
    npz = base / "buffers.npz"
    packed = _load_npz(npz, CandidateError) if npz.is_file() else {}
    out = {}
    for key, spec in specs.items():
        if key in packed:
            a, source, step = packed[key], f"{scene}/buffers.npz:{key}", 0.0
        elif (base / f"{key}.npy").is_file():
            source, step = f"{scene}/{key}.npy", 0.0
            try:
                with open(base / f"{key}.npy", "rb") as fh:
                    a = np.load(fh, allow_pickle=False)
                    if not isinstance(a, np.ndarray):
                        raise ValueError("not an .npy array")
            except (OSError, ValueError, EOFError) as exc:
                raise CandidateError(f"cannot read candidate {source}: {exc}") from None
        elif (base / f"{key}.png").is_file():
            source = f"{scene}/{key}.png"
            try:
                img = iio.imread(base / f"{key}.png", extension=".png")
                a, step = png_decode(img, spec["kind"], spec["shape"])
            except (OSError, ValueError, SyntaxError) as exc:
                raise CandidateError(f"cannot use candidate {source}: {exc}") from None
        else:
            looked = [f"{scene}/buffers.npz", f"{scene}/{key}.npy", f"{scene}/{key}.png"]
            raise CandidateError(f"candidate buffer {scene}/{key} is missing (looked for "
                                 f"{', '.join(looked)} in {candidate_dir})")
        out[key] = (_check_candidate(scene, key, spec, np.asarray(a), source), source, step)
    return out


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


def buffer_allowance(spec, arrays, *, step=0.0, clear_depth=1.0):
    """The allowance one buffer's tolerant checks use, as the report shows it per pixel.

    Parameters
    ----------
    spec : dict
        The buffer's ``"tolerant"`` manifest entry.
    arrays : dict
        The scene's ``tolerance.npz`` (:mod:`refraster.golden.allowance`).
    step, clear_depth : float
        As passed to :func:`refraster.golden.allowance.tolerant_metrics`.

    Returns
    -------
    dict
        ``checks``, ``step``, ``clear_depth`` and the arrays (not copied) the checks read:
        ``id_may``, and where they apply ``coverage``, ``lo``/``hi``, ``angle``, ``may``.
    """
    out = {"checks": list(spec["checks"]), "step": float(step),
           "clear_depth": float(clear_depth), "id_may": arrays["id_may"]}
    for key in ("lo", "hi", "angle"):
        if key in spec:
            out[key] = arrays[spec[key]]
    if "coverage" in spec["checks"]:
        out["coverage"] = arrays["coverage"]
    if "masked" in spec["checks"]:
        out["may"] = arrays[spec.get("may", "may")]
    return out


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
        ref = _reference(golden_dir, name, entry)
        allow = _allowance_arrays(golden_dir, name, entry) if mode == "tolerant" else None
        try:
            cand = load_candidate(candidate_dir, name, entry["buffers"])
        except CandidateError as exc:
            results.append(SceneResult(name, "error", [], str(exc)))
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
                allowance = buffer_allowance(spec["tolerant"], allow, step=step,
                                             clear_depth=clear)
            else:
                metrics, checks, images = buffer_metrics(ref[key], a, spec["kind"], tol,
                                                         step=step)
                allowance = None
            buffers.append(BufferResult(key, spec["kind"], source, tol, metrics, checks,
                                        ref[key], a, images, allowance))
        status = "pass" if all(b.passed for b in buffers) else "fail"
        results.append(SceneResult(name, status, buffers))
    comparison = Comparison(golden_dir, candidate_dir, "tolerant" if mode == "tolerant"
                            else profile, results, mode="tolerant" if mode == "tolerant"
                            else "profile")
    if report is not None:
        from .report import write_report
        comparison.report_dir = write_report(report, comparison, manifest)
    return comparison
