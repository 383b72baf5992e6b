"""The HTML report of a comparison, written for the GPU developer who reads it first.

Failing scenes come first, open; passing ones are one collapsed line each (``<details>``), with a
scene table at the top linking to every scene. In a failing scene the failing buffers come first;
each shows a crop around the pixels outside the allowance (their bounding box, padded, at most
:data:`CROP_MAX` pixels a side around the worst pixel), magnified with nearest-neighbour scaling
and a pixel grid (one pixel ≥ :data:`MIN_ZOOM` screen pixels) as reference, candidate,
difference and error mask side by side, then its metrics and checks and the five full-size
pictures (reference, candidate, difference, error mask, FLIP map). Hovering a pixel of a crop —
or of a failing buffer's full-size picture inside the crop — shows its row, column, reference
and candidate values, the allowed interval or set and whether it is outside the allowance.

The crop's values are embedded in the page (no server; it works from ``file://``): per failing
buffer one ``<script type="application/json">`` holding the little-endian typed arrays of the
crop, deflated and base64-encoded, decoded by the page's script (``DecompressionStream``) on the
first hover. Metric cells that do not apply say why in a tooltip (``title``). The page states the
compare mode and the golden's schema version. Every text taken from the comparison, the manifest
or a path is escaped (``html.escape``; JSON with ``<``, ``>`` and ``&`` as ``\\u`` escapes).

The page and its PNGs (``img/``) are built in a temporary sibling directory and committed by
:mod:`refraster.golden.io.write` (locked, atomic, replacing only a report refraster wrote), like a
golden.
"""

from __future__ import annotations

import base64
import html
import json
import math
import shutil
import zlib
from pathlib import Path

import numpy as np

from ... import io as rio
from ..allowances.precision import manifest_candidate_bits
from ..io.buffers import preview, preview_range
from ..io import write

__all__ = ["write_report", "check_report_dir", "difference_image", "mask_image", "crop_box",
           "crop_zoom", "magnify", "failing_pixels", "scene_order", "CROP_MAX", "CROP_PAD",
           "MIN_ZOOM"]

#: Largest side of a magnified crop (pixels of the buffer), its padding around the bounding box
#: of the failing pixels, the smallest magnification (screen pixels per buffer pixel) and the
#: screen size the longer side of a crop is magnified towards.
CROP_MAX, CROP_PAD, MIN_ZOOM, CROP_SCREEN = 32, 4, 8, 256
#: The crops of the first failing buffers load with the page (the first screen); the others,
#: like every full-size picture, when they come near the viewport (``loading="lazy"``).
EAGER_CROPS = 4

_CSS = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1em 1.5em; color: #222; }
h1 { font-size: 1.3em; margin: .2em 0; } h2 { font-size: 1.15em; margin: 1em 0 .3em; }
h3 { font-size: 1.02em; margin: .3em 0; }
.pass { color: #176b2c; } .fail { color: #b3261e; } .error { color: #8a4b00; }
.meta { margin: .2em 0; font-size: 13px; }
.scenes { max-height: 24vh; overflow: auto; display: inline-block; border: 1px solid #ddd; }
table.metrics { border-collapse: collapse; margin: .4em 0; }
table.metrics td, table.metrics th { border: 1px solid #ccc; padding: 2px 8px; text-align: right; }
.scenes table.metrics { margin: 0; } .scenes td { text-align: left; }
td.na { color: #888; cursor: help; text-decoration: underline dotted; }
.row { display: flex; gap: 12px; flex-wrap: wrap; align-items: flex-start; }
figure { margin: 0; } figcaption { font-size: 12px; color: #555; text-align: center; }
img { image-rendering: pixelated; border: 1px solid #999; background: #fff; display: block; }
img.px { cursor: crosshair; }
span.na { display: inline-block; border: 1px dashed #bbb; color: #888; text-align: center; }
.buffer { border-top: 1px solid #ddd; padding: .4em 0; }
section.buffer { content-visibility: auto; contain-intrinsic-size: auto 900px; }
.why { margin: .2em 0; font-size: 13px; } .note { font-size: 12px; color: #555; margin: .2em 0; }
.frame { position: relative; display: inline-block; }
.box { position: absolute; border: 1px solid #00b7ff; box-shadow: 0 0 0 1px #fff;
       pointer-events: none; }
details > summary { cursor: pointer; padding: 2px 0; }
details.scene > summary { font-size: 1.05em; font-weight: 600; }
section.scene > h2 { border-bottom: 2px solid #b3261e; }
#tip { position: fixed; z-index: 10; max-width: 560px; padding: 6px 8px; font: 12px/1.35
       ui-monospace, monospace; white-space: pre-wrap; background: #fffbe6; color: #111;
       border: 1px solid #777; box-shadow: 2px 2px 6px rgba(0, 0, 0, .25);
       pointer-events: none; }
code { background: #f3f3f3; padding: 0 3px; }
"""

# The page's one script: maps the pointer to a buffer pixel, decodes the crop's embedded arrays
# on first use and writes the pixel's values into the tooltip (textContent only: nothing is
# parsed as HTML); opens a collapsed scene or buffer that a link targets and fills in its
# pictures when it is first opened.
_SCRIPT = r"""
(function () {
  "use strict";
  const TYPES = {f4: Float32Array, f8: Float64Array, i4: Int32Array, i1: Int8Array,
                 u1: Uint8Array};
  const tip = document.getElementById("tip");
  const cache = new Map();
  function decode(id) {
    if (cache.has(id)) return cache.get(id);
    const el = document.getElementById(id);
    const entry = {meta: null, error: null};
    cache.set(id, entry);
    if (!el) { entry.error = "no embedded data"; return entry; }
    let meta, bin;
    try {
      meta = JSON.parse(el.textContent);
      bin = Uint8Array.from(atob(meta.b64), c => c.charCodeAt(0));
    } catch (err) {
      entry.error = "unreadable embedded data: " + err;
      return entry;
    }
    if (typeof DecompressionStream === "undefined") {
      entry.error = "this browser cannot inflate the embedded data (no DecompressionStream)";
      return entry;
    }
    entry.promise = new Response(new Blob([bin]).stream().pipeThrough(
        new DecompressionStream("deflate"))).arrayBuffer().then(buf => {
      meta.a = {};
      for (const [name, spec] of Object.entries(meta.arrays)) {
        meta.a[name] = new TYPES[spec[0]](buf, spec[1], spec[2]);
      }
      entry.meta = meta;
    }, err => { entry.error = String(err); });
    return entry;
  }
  function num(x, dt) {
    if (Number.isNaN(x)) return "NaN";
    if (!Number.isFinite(x)) return x > 0 ? "inf" : "-inf";
    if (dt === "f4") {
      for (let p = 1; p <= 9; p++) {
        const v = Number(x.toPrecision(p));
        if (Math.fround(v) === x) return String(v);
      }
    }
    return String(x);
  }
  function values(m, name, i) {
    const a = m.a[name], dt = m.arrays[name][0], c = m.channels, out = [];
    for (let k = 0; k < c; k++) out.push(a[i * c + k]);
    return out.map(v => m.kind === "bool" ? (v ? "true" : "false") : num(v, dt));
  }
  function raw(m, name, i) {
    const a = m.a[name], c = m.channels, out = [];
    for (let k = 0; k < c; k++) out.push(a[i * c + k]);
    return out;
  }
  function vec(list) { return list.length === 1 ? list[0] : "(" + list.join(", ") + ")"; }
  const COVER = ["must not be covered", "may be covered", "must be covered"];
  function allowed(m, i) {
    const A = m.a, out = [];
    const free = A.id_may ? A.id_may[i] : 0;
    const ref = raw(m, "ref", i), cand = raw(m, "cand", i);
    const cov = A.coverage ? A.coverage[i] : -1;
    if (m.mode === "profile" || m.checks.includes("masked")) {
      const t = A.thr[i], may = A.may && A.may[i];
      // the pixel's error as the compare measures it: equal values (infinities too) 0, NaN inf
      const err = Math.max(...ref.map((r, k) => {
        const d = r === cand[k] ? 0 : Math.abs(cand[k] - r);
        return Number.isNaN(d) ? Infinity : d;
      }));
      out.push("|candidate - reference| <= " + num(t, "f8") + " per channel: " +
               vec(ref.map(r => "[" + num(r - t, "f8") + ", " + num(r + t, "f8") + "]")));
      if (m.radius > 0) {
        out.push("or the values match within " + m.radius + " px both ways (position " +
                 "deviation)" + (A.status[i] === 1 && err > t && !may ? ": forgiven here" : ""));
      }
      if (may) out.push("may-region: any value is allowed here");
    }
    for (const ch of m.checks) {
      if (ch === "coverage" && m.kind === "id") {
        const r = ref[0];
        let set;
        if (cov === 0) set = "{background (< 0)}";
        else if (free || r < 0) set = cov === 2 ? "any id >= 0" : "any id, or background (< 0)";
        else set = cov === 2 ? "{" + r + "}" : "{" + r + ", background (< 0)}";
        out.push("allowed set: " + set + " (coverage: " + COVER[cov] + "; " +
                 (free ? "the visible primitive may differ" : "the id must agree") + ")");
      } else if (ch === "coverage") {
        out.push("coverage (value " + (m.greater ? ">" : "<") + " clear depth " +
                 num(m.clear, "f8") + "): " + COVER[cov]);
      } else if (ch === "id" && m.kind !== "id") {
        out.push("allowed set: " + (free ? "{false, true} (the visible primitive may differ)"
                                         : "{" + values(m, "ref", i).join(", ") + "}"));
      } else if (ch === "interval") {
        if (free) { out.push("interval: not checked (the visible primitive may differ here)"); }
        else if (A.coverage && cov !== 2) {
          out.push("interval: not checked (coverage is not required here)");
        } else if (A.coverage && (m.greater ? cand[0] <= m.clear : cand[0] >= m.clear)) {
          out.push("interval: not checked (the candidate does not cover this pixel)");
        } else {
          const lo = raw(m, "lo", i), hi = raw(m, "hi", i);
          out.push("allowed interval: " + vec(lo.map((l, k) =>
            "[" + num(l - m.step, m.step ? "f8" : "f4") + ", " +
            num(hi[k] + m.step, m.step ? "f8" : "f4") + "]")));
        }
      } else if (ch === "face" && m.face && m.face[i]) {
        out.push("face check (the visible primitive may differ here): " + m.face[i]);
      } else if (ch === "angle") {
        if (free) { out.push("angle: not checked (the visible primitive may differ here)"); }
        else {
          out.push("angle(reference, candidate) = " + Number(A.angle_value[i].toPrecision(6)) +
                   " rad, allowed <= " + (m.step ? num(A.angle[i] + m.step * Math.sqrt(3), "f8")
                                                 : num(A.angle[i], "f4")) + " rad");
        }
      }
    }
    return out.join("\n");
  }
  const STATUS = ["equal", "differs, allowed", "OUTSIDE THE ALLOWANCE"];
  function describe(el, row, col) {
    const head = "row " + row + ", col " + col + "  (" + el.dataset.name + ")";
    const id = el.dataset.d;
    if (!id) {
      return {text: head + "\nvalues are embedded for the magnified crops of failing " +
                    "buffers only"};
    }
    const entry = decode(id);
    if (entry.error) return {text: head + "\n" + entry.error};
    if (!entry.meta) return {text: head + "\n...", pending: entry.promise};
    const m = entry.meta;
    const r = row - m.origin[0], c = col - m.origin[1];
    if (r < 0 || c < 0 || r >= m.rows || c >= m.cols) {
      return {text: head + "\noutside the magnified crop (rows " + m.origin[0] + "-" +
                    (m.origin[0] + m.rows - 1) + ", cols " + m.origin[1] + "-" +
                    (m.origin[1] + m.cols - 1) + "): values are embedded for the crop only"};
    }
    const i = r * m.cols + c;
    return {text: [head, "reference: " + vec(values(m, "ref", i)),
                   "candidate: " + vec(values(m, "cand", i)),
                   allowed(m, i), "status: " + STATUS[m.a.status[i]]].join("\n")};
  }
  let last = null;
  function show(ev) {
    const el = ev.target;
    const rect = el.getBoundingClientRect();
    const rows = +el.dataset.rows, cols = +el.dataset.cols;
    const col = +el.dataset.c0 + Math.min(cols - 1, Math.max(0,
                  Math.floor((ev.clientX - rect.left - el.clientLeft) / el.clientWidth * cols)));
    const row = +el.dataset.r0 + Math.min(rows - 1, Math.max(0,
                  Math.floor((ev.clientY - rect.top - el.clientTop) / el.clientHeight * rows)));
    last = {el: el, row: row, col: col, x: ev.clientX, y: ev.clientY};
    render();
  }
  function render() {
    if (!last) return;
    const d = describe(last.el, last.row, last.col);
    tip.textContent = d.text;
    tip.dataset.row = last.row;
    tip.dataset.col = last.col;
    tip.hidden = false;
    const x = Math.min(last.x + 16, window.innerWidth - tip.offsetWidth - 4);
    const y = last.y + 16 + tip.offsetHeight > window.innerHeight ?
              Math.max(0, last.y - 16 - tip.offsetHeight) : last.y + 16;
    tip.style.left = Math.max(0, x) + "px";
    tip.style.top = y + "px";
    if (d.pending) d.pending.then(render);
  }
  window.addEventListener("scroll", () => { last = null; tip.hidden = true; });
  document.addEventListener("mousemove", ev => {
    if (ev.target.classList && ev.target.classList.contains("px")) show(ev);
    else if (last) { last = null; tip.hidden = true; }
  });
  // the pictures of a collapsed scene or buffer wait in a <template> until it is first opened
  function expand(details) {
    for (const t of details.querySelectorAll(":scope > template.later")) {
      t.replaceWith(t.content.cloneNode(true));
    }
  }
  document.addEventListener("toggle", ev => {
    if (ev.target.open) expand(ev.target);
  }, true);
  function openTarget() {
    const t = location.hash && document.getElementById(decodeURIComponent(location.hash.slice(1)));
    for (let e = t; e; e = e.parentElement) if (e.tagName === "DETAILS") e.open = true;
    if (t) t.scrollIntoView();
  }
  window.addEventListener("hashchange", openTarget);
  openTarget();
})();
"""


def _ramp(t):
    """Black → red → yellow → white for t in [0, 1]."""
    t = np.clip(t, 0.0, 1.0)
    r = np.clip(3.0 * t, 0.0, 1.0)
    g = np.clip(3.0 * t - 1.0, 0.0, 1.0)
    b = np.clip(3.0 * t - 2.0, 0.0, 1.0)
    return (np.stack([r, g, b], axis=-1) * 255.0 + 0.5).astype(np.uint8)


def difference_image(error):
    """Per-pixel error on a log scale from the smallest to the largest non-zero finite error
    (so a 1e-6 depth error next to a 0.3 colour error still shows); zero black, non-finite
    white."""
    e = np.asarray(error, np.float64)
    positive = np.isfinite(e) & (e > 0)
    t = np.where(np.isfinite(e), 0.0, 1.0)
    if positive.any():
        lo, hi = float(e[positive].min()), float(e[positive].max())
        span = np.log(hi / lo) if hi > lo else 1.0
        t[positive] = 0.25 + 0.75 * np.log(e[positive] / lo) / span
    return _ramp(t)


def mask_image(reference_preview, over, forgiven, may=None):
    """Faded reference; the tolerant "may" region light blue, forgiven pixels yellow, failing
    pixels (outside the allowance) red."""
    img = (reference_preview.astype(np.float64) * 0.3 + 255.0 * 0.7).astype(np.uint8)
    if may is not None:
        img[may] = (150, 200, 255)
    img[forgiven] = (240, 190, 0)
    img[over & ~forgiven] = (220, 0, 0)
    return img


def check_report_dir(report, golden_dir, candidate_dir):
    """Refuse a report directory that would write into (or replace) the golden or candidate
    directory, or that holds anything but a report refraster wrote
    (:func:`refraster.golden.io.write.check_report_dir`)."""
    return write.check_report_dir(report, golden_dir, candidate_dir)


def _fmt(x):
    if x is None:
        return "—"
    if isinstance(x, float):
        return str(x) if not math.isfinite(x) else f"{x:.4g}"
    return html.escape(str(x))


def _attr(x):
    return html.escape(str(x), quote=True)


def _json_script(obj):
    """JSON that can sit inside ``<script>``: ``<``, ``>`` and ``&`` as ``\\u`` escapes."""
    return (json.dumps(obj, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
            .replace(">", "\\u003e").replace("&", "\\u0026"))


# --- the crop -----------------------------------------------------------------------------------

def failing_pixels(b):
    """(H, W) bool: the pixels of a buffer result outside the allowance (unforgiven)."""
    return np.asarray(b.images["over"], np.bool_) & ~np.asarray(b.images["forgiven"], np.bool_)


def crop_box(bad, error, worst=None, *, pad=CROP_PAD, limit=CROP_MAX):
    """The crop the report magnifies: the bounding box of ``bad`` (else of the pixels that
    differ) grown by ``pad`` pixels and clipped to the picture; a box longer than ``limit`` on a
    side is cut to ``limit`` around ``worst`` (``{"row", "col"}``, else the box's centre).

    Returns ``((r0, r1, c0, c1), (R0, R1, C0, C1))`` — the crop and the unpadded bounding box,
    half-open — or ``None`` when no pixel differs.
    """
    bad = np.asarray(bad, np.bool_)
    h, w = bad.shape
    pts = np.argwhere(bad)
    if not len(pts):
        pts = np.argwhere(np.asarray(error) > 0)
    if not len(pts):
        return None
    (R0, C0), (R1, C1) = pts.min(axis=0), pts.max(axis=0) + 1
    box = []
    for lo, hi, n, key in ((R0, R1, h, "row"), (C0, C1, w, "col")):
        lo, hi = max(int(lo) - pad, 0), min(int(hi) + pad, n)
        if hi - lo > limit:
            centre = (int(worst[key]) if worst is not None and lo <= worst[key] < hi
                      else (lo + hi) // 2)
            lo = min(max(centre - limit // 2, 0), n - limit)
            hi = lo + limit
        box += [lo, hi]
    return tuple(box), (int(R0), int(R1), int(C0), int(C1))


def crop_zoom(rows, cols):
    """Screen pixels per buffer pixel: at least :data:`MIN_ZOOM`, more for small crops."""
    return max(MIN_ZOOM, min(3 * MIN_ZOOM, CROP_SCREEN // max(rows, cols, 1)))


def magnify(img, zoom):
    """Nearest-neighbour magnification of an (H, W, 3) uint8 picture by ``zoom`` with a pixel
    grid: the first row and column of every magnified pixel is pulled 40 % towards black
    (bright pixels) or white (dark ones)."""
    big = np.repeat(np.repeat(np.asarray(img, np.uint8), zoom, axis=0), zoom, axis=1)
    base = big.copy()

    def line(v):
        v = v.astype(np.float32)
        target = np.where(v.mean(axis=-1, keepdims=True) > 110.0, 0.0, 255.0)
        return (0.6 * v + 0.4 * target + 0.5).astype(np.uint8)
    big[:, ::zoom] = line(base[:, ::zoom])
    big[::zoom] = line(base[::zoom])
    return big


def _typed(a):
    """(little-endian array, JS type) for embedding: float32 stays float32, other floats
    float64, integers int32 (float64 beyond its range), bools uint8."""
    a = np.asarray(a)
    if a.dtype == np.bool_:
        return a.astype("u1"), "u1"
    if np.issubdtype(a.dtype, np.integer):
        if a.size == 0 or (int(a.min()) >= -2 ** 31 and int(a.max()) < 2 ** 31):
            return a.astype("<i4"), "i4"
        return a.astype("<f8"), "f8"
    if a.dtype in (np.float32, np.float16):
        return a.astype("<f4"), "f4"
    return a.astype("<f8"), "f8"


def _crop_data(b, box, bad):
    """The crop's values for the page's read-out: JSON metadata and the arrays, deflated."""
    from ..allowances.core import _angle
    from .metrics import local_variation
    r0, r1, c0, c1 = box
    sl = (slice(r0, r1), slice(c0, c1))
    ref, cand = np.asarray(b.reference)[sl], np.asarray(b.candidate)[sl]
    err = np.asarray(b.images["error"])[sl]
    status = np.where(bad[sl], 2, np.where(err > 0, 1, 0)).astype(np.uint8)
    arrays = {"ref": ref, "cand": cand, "status": status}
    al = b.allowance
    meta = {"kind": b.kind, "rows": r1 - r0, "cols": c1 - c0, "origin": [r0, c0],
            "channels": int(ref.shape[2]) if ref.ndim == 3 else 1}
    if al is not None:
        meta.update(mode="tolerant", checks=al["checks"], step=al["step"],
                    clear=al["clear_depth"],
                    greater=al.get("depth_func", "less") in ("greater", "gequal"))
        for key in ("id_may", "coverage", "lo", "hi", "angle", "may"):
            if key in al:
                arrays[key] = np.asarray(al[key])[sl]
        if "angle" in al:
            arrays["angle_value"] = _angle(ref, cand)
        if "sets" in al:   # where the id may differ: what the face check admits, in words
            from ..allowances.core import face_allowed
            may = np.asarray(al["id_may"])
            meta["face"] = [face_allowed(b.name, al["sets"], r, c, al["named"], al["step"])
                            if may[r, c] else None
                            for r in range(r0, r1) for c in range(c0, c1)]
    else:
        meta.update(mode="profile", checks=[])
    if al is None or "masked" in al["checks"]:
        t = b.tolerance
        slope = float(t.get("slope") or 0.0)
        thr = np.full(ref.shape[:2], float(b.metrics["threshold"]))
        if slope > 0:
            h, w = np.shape(b.reference)[:2]
            e0, e1, f0, f1 = max(r0 - 1, 0), min(r1 + 1, h), max(c0 - 1, 0), min(c1 + 1, w)
            v = local_variation(np.asarray(b.reference)[e0:e1, f0:f1])
            thr = thr + slope * v[r0 - e0:r0 - e0 + (r1 - r0), c0 - f0:c0 - f0 + (c1 - c0)]
        arrays["thr"] = thr
        meta["radius"] = int(t.get("deviation_radius", 0))
    blob, specs = bytearray(), {}
    for name, arr in arrays.items():
        typed, js = _typed(arr)
        data = np.ascontiguousarray(typed).tobytes()
        specs[name] = [js, len(blob), int(typed.size)]
        blob += data + b"\0" * (-len(data) % 8)
    meta["arrays"] = specs
    meta["b64"] = base64.b64encode(zlib.compress(bytes(blob), 9)).decode("ascii")
    return meta


# --- the page -----------------------------------------------------------------------------------

def _figure(src, caption, width, height, zoom, *, hover=None, box=None, lazy=True, why=""):
    """A picture (``hover``: its data attributes for the read-out; ``box``: the crop outlined;
    ``why``: the tooltip of a missing picture)."""
    if src is None:
        return (f'<figure><span class="na" title="{_attr(why)}" style="width:{width * zoom}px;'
                f'height:{height * zoom}px;line-height:{height * zoom}px">n/a</span>'
                f"<figcaption>{caption}</figcaption></figure>")
    attrs = ' loading="lazy"' if lazy else ""
    if hover is not None:
        attrs += ' class="px"' + "".join(f' data-{k}="{_attr(v)}"' for k, v in hover.items())
    img = (f'<img src="{_attr(src)}" width="{width * zoom}" height="{height * zoom}" '
           f'alt="{_attr(caption)}"{attrs}>')
    if box is not None:
        r0, r1, c0, c1 = box
        img = (f'<span class="frame">{img}<span class="box" style="top:{r0 * zoom + 1}px;'
               f"left:{c0 * zoom + 1}px;width:{(c1 - c0) * zoom}px;"
               f'height:{(r1 - r0) * zoom}px"></span></span>')
    return f"<figure>{img}<figcaption>{caption}</figcaption></figure>"


def _na(reason):
    return f'<td class="na" title="{_attr(reason)}">n/a</td>'


def _metrics_table(b, tolerant):
    """The metric cells; one that does not apply says why in its tooltip."""
    m = b.metrics
    checks = b.tolerance.get("tolerant", {}).get("checks", []) if tolerant else []
    masked = "masked" in checks
    cells = [f"<td>{_fmt(m['max_abs'])}</td>", f"<td>{_fmt(m['rmse'])}</td>"]
    if m["psnr"] == math.inf:
        cells.append(f'<td title="{_attr("no error: PSNR is infinite")}">inf</td>')
    else:
        cells.append(f"<td>{_fmt(m['psnr'])}</td>")
    if tolerant and not masked:
        why = ("tolerant mode: this buffer is checked against its per-pixel allowance ("
               + ", ".join(checks) + "), not against a global threshold")
        cells.append(_na(why))
    else:
        cells.append(f"<td>{_fmt(m['threshold'])}</td>")
    cells.append(f"<td>{m['n_over']} ({_fmt(m['fraction_over'])})</td>")
    cells.append(f"<td>{m['n_unforgiven']} ({_fmt(m['fraction_unforgiven'])})</td>")
    if tolerant and not masked:
        cells.append(_na("tolerant mode: no position-deviation compare for this buffer; its "
                         "allowance already holds what a shifted sample may change"))
    else:
        cells.append(f"<td>{b.tolerance['deviation_radius']}</td>")
    if b.kind != "color":
        cells.append(_na(f"FLIP is a perceptual difference of colour pictures; {b.name} is a "
                         f"{b.kind} buffer"))
    elif m.get("flip_mean") is None:
        cells.append(_na("FLIP was not computed: the flip-evaluator package is not installed"))
    else:
        cells.append(f"<td>{_fmt(m['flip_mean'])}</td>")
    over = "differ" if tolerant else "over threshold"
    bad = "outside allowance" if tolerant else "unforgiven"
    head = "".join(f"<th>{x}</th>" for x in ("max abs", "RMSE", "PSNR", "threshold", over, bad,
                                             "radius", "FLIP"))
    rows = "".join(
        f"<tr><td>{html.escape(c['metric'])}</td><td>{_fmt(c['value'])}</td>"
        f"<td>{html.escape(c['op'])} {_fmt(c['limit'])}</td>"
        f"<td class=\"{'pass' if c['ok'] else 'fail'}\">{'ok' if c['ok'] else 'FAIL'}</td></tr>"
        for c in b.checks)
    return (f'<div class="row"><table class="metrics"><tr>{head}</tr><tr>{"".join(cells)}</tr>'
            f'</table><table class="metrics"><tr><th>check</th><th>value</th><th>limit</th>'
            f"<th></th></tr>{rows}</table></div>")


class _Page:
    """State while one page is built: the report's root and a counter for element ids."""

    def __init__(self, root, tolerant):
        self.root, self.tolerant, self.n = root, tolerant, 0

    def next_id(self):
        self.n += 1
        return f"d{self.n}"


def _buffer_html(page, scene, b):
    root = page.root
    h, w = b.reference.shape[:2]
    zoom = 2 if w <= 128 else 1
    vr = preview_range(b.reference, b.kind)
    ref_png = preview(b.reference, b.kind, vr)
    cand_png = preview(b.candidate, b.kind, vr)
    diff_png = difference_image(b.images["error"])
    mask_png = mask_image(ref_png, b.images["over"], b.images["forgiven"], b.images.get("may"))
    stem = f"img/{scene}__{b.name}"
    rio.write_png(root / f"{stem}__reference.png", ref_png)
    rio.write_png(root / f"{stem}__candidate.png", cand_png)
    rio.write_png(root / f"{stem}__difference.png", diff_png)
    rio.write_png(root / f"{stem}__mask.png", mask_png)
    flip = None
    if b.images["flip"] is not None:
        flip = f"{stem}__flip.png"
        rio.write_png(root / flip, b.images["flip"])
    m = b.metrics
    status = "pass" if b.passed else "fail"
    name = f"{scene}/{b.name}"
    mask_caption = ("error mask: red outside the allowance, yellow allowed, blue may-region"
                    if "may" in b.images else "error mask: red fails, yellow forgiven")
    title = (f'{html.escape(b.name)} <small>({html.escape(b.kind)}, from '
             f'<code>{html.escape(b.source)}</code>)</small> <span class="{status}">'
             f"{status.upper()}</span>")
    crop_html, box, data_id = "", None, ""
    if not b.passed:
        bad = failing_pixels(b)
        found = crop_box(bad, b.images["error"], m.get("worst"))
        if found is None:
            crop_html = ('<p class="note">No pixel differs: the buffer fails on a metric '
                         "alone, so there is no crop to magnify.</p>")
        else:
            box, (R0, R1, C0, C1) = found
            r0, r1, c0, c1 = box
            rows, cols = r1 - r0, c1 - c0
            cz = crop_zoom(rows, cols)
            data_id = page.next_id()
            hover = {"d": data_id, "name": name, "r0": r0, "c0": c0, "rows": rows,
                     "cols": cols}
            n_bad = int(bad.sum())
            what = (f"the {n_bad} pixel{'s' if n_bad != 1 else ''} outside the allowance"
                    if n_bad else "the pixels that differ")
            padded = (min(R1 + CROP_PAD, h) - max(R0 - CROP_PAD, 0),
                      min(C1 + CROP_PAD, w) - max(C0 - CROP_PAD, 0))
            cut = ("" if (rows, cols) == padded else
                   f"; longer than {CROP_MAX} px, cut around the worst pixel")
            figs = []
            for label, img in (("reference", ref_png), ("candidate", cand_png),
                               ("difference", diff_png), ("error mask", mask_png)):
                src = f"{stem}__crop_{label.replace(' ', '_')}.png"
                rio.write_png(root / src, magnify(img[r0:r1, c0:c1], cz))
                figs.append(_figure(src, label, cols, rows, cz, hover=hover,
                                    lazy=page.n > EAGER_CROPS))
            meta = _crop_data(b, box, bad)
            crop_html = (
                f'<p class="note">Magnified ×{cz}: rows {r0}–{r1 - 1}, columns {c0}–{c1 - 1} '
                f"(bounding box of {what}: rows {R0}–{R1 - 1}, columns {C0}–{C1 - 1}, padded by "
                f"{CROP_PAD}{cut}). Hover a pixel for its values.</p>"
                f'<div class="row crop">{"".join(figs)}</div>'
                f'<script type="application/json" id="{data_id}">{_json_script(meta)}</script>')
    hover = {"d": data_id, "name": name, "r0": 0, "c0": 0, "rows": h, "cols": w}
    figures = "".join([
        _figure(f"{stem}__reference.png", "reference", w, h, zoom, hover=hover, box=box),
        _figure(f"{stem}__candidate.png", "candidate", w, h, zoom, hover=hover, box=box),
        _figure(f"{stem}__difference.png", f"difference (max {_fmt(m['max_abs'])})", w, h, zoom,
                hover=hover, box=box),
        _figure(f"{stem}__mask.png", mask_caption, w, h, zoom, hover=hover, box=box),
        _figure(flip, "FLIP" + (f" (mean {_fmt(m.get('flip_mean'))})" if flip else ""),
                w, h, zoom, hover=hover if flip else None, box=box,
                why="FLIP applies to colour buffers only" if b.kind != "color" else
                "FLIP was not computed: the flip-evaluator package is not installed"),
    ])
    table = _metrics_table(b, page.tolerant)
    full = f'<div class="row full">{figures}</div>'
    if b.passed:
        return (f'<details class="buffer pass"><summary>{title} — max abs {_fmt(m["max_abs"])}'
                f'</summary>{table}<template class="later">{full}</template></details>')
    why = "; ".join(f"{c['metric']}: {c.get('detail') or _plain(c)}"
                    for c in b.checks if not c["ok"])
    return (f'<section class="buffer fail"><h3>{title}</h3><p class="why fail">'
            f"{html.escape(why)}</p>{crop_html}{table}{full}</section>")


def _plain(c):
    """``value > limit`` of a failed check, not yet escaped."""
    def num(x):
        return f"{x:.4g}" if isinstance(x, float) and math.isfinite(x) else str(x)
    bad = ">" if c["op"] == "<=" else "<"
    return f"{num(c['value'])} {bad} {num(c['limit'])}"


def scene_order(scenes):
    """Unusable and failing scenes first, then passing ones; each group in the compare's order."""
    return ([s for s in scenes if s.status == "error"] + [s for s in scenes if s.status == "fail"]
            + [s for s in scenes if s.status not in ("error", "fail")])


def _scene_html(page, s, entry):
    sid = _attr(s.name)
    head = (f'{html.escape(s.name)} <span class="{s.status}">{s.status.upper()}</span>')
    about = (f"<p>{html.escape(entry['description'])} Technique "
             f"<code>{html.escape(entry['technique'])}</code>.</p>")
    if s.error:
        return (f'<section class="scene" id="{sid}"><h2>{head}</h2>{about}'
                f'<p class="error">Unusable candidate: {html.escape(s.error)}</p></section>')
    failing = [b for b in s.buffers if not b.passed]
    passing = [b for b in s.buffers if b.passed]
    body = "".join(_buffer_html(page, s.name, b) for b in failing + passing)
    if s.status == "fail":
        return f'<section class="scene" id="{sid}"><h2>{head}</h2>{about}{body}</section>'
    return (f'<details class="scene" id="{sid}"><summary>{head} — {len(s.buffers)} buffers'
            f"</summary>{about}{body}</details>")


def _mode_text(comparison):
    if comparison.mode == "tolerant":
        return ("tolerant: the golden's stored per-pixel allowances (coverage masks, value "
                "intervals, normal angles); buffers without an interval use the conformant "
                "profile with the may-region forgiven")
    if comparison.profile == "exact":
        return "exact: bit-exact (profile exact, threshold 0)"
    return f"profile {comparison.profile}: the per-buffer metric thresholds of the manifest"


def _page(root, comparison, manifest):
    """The page's HTML; writes the pictures into ``root / "img"``."""
    page = _Page(root, comparison.mode == "tolerant")
    verdict = ["PASS", "FAIL", "UNUSABLE INPUT"][comparison.exit_code]
    verdict_class = ["pass", "fail", "error"][comparison.exit_code]
    ordered = scene_order(comparison.scenes)
    overview = []
    for s in ordered:
        failing = ", ".join(f"{b.name}: {m}" for b in s.buffers for m in b.failed_metrics)
        overview.append(
            f'<tr><td><a href="#{_attr(s.name)}">{html.escape(s.name)}</a></td>'
            f'<td class="{s.status}">{s.status.upper()}</td>'
            f"<td>{html.escape(failing or s.error or '')}</td></tr>")
    sections = "".join(_scene_html(page, s, manifest["scenes"][s.name]) for s in ordered)
    gen = manifest["generator"]
    counts = {k: sum(s.status == k for s in ordered) for k in ("fail", "error", "pass")}
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<link rel=\"icon\" href=\"data:,\">"
        f"<title>refraster golden compare: {verdict}</title><style>{_CSS}</style></head>"
        f"<body><div id=\"tip\" role=\"tooltip\" hidden></div>"
        f"<h1>Golden compare: <span class=\"{verdict_class}\">{verdict}</span> "
        f"<small>({counts['fail']} failing, {counts['error']} unusable, {counts['pass']} passing "
        f"scenes)</small></h1>"
        f'<p class="meta">Compare mode <b>{html.escape(_mode_text(comparison))}</b>. Golden '
        f"<code>{html.escape(str(comparison.golden_dir))}</code>: schema "
        f"<code>{html.escape(str(manifest.get('schema')))}</code> version "
        f"<b>{html.escape(str(manifest.get('schema_version')))}</b>, refraster "
        f"{html.escape(gen['refraster'])}, numpy {html.escape(gen['numpy'])}, numba "
        f"{html.escape(gen['numba'])}; {html.escape(str(manifest['raster']['subpixel_bits']))} "
        f"sub-pixel bits, fill rule {html.escape(manifest['raster']['fill_rule'])}; "
        f"allowances for a candidate of {manifest_candidate_bits(manifest)} sub-pixel bits. "
        f"Candidate "
        f"<code>{html.escape(str(comparison.candidate_dir))}</code>.</p>"
        f'<div class="scenes"><table class="metrics"><tr><th>scene</th><th>status</th>'
        f"<th>failing</th></tr>{''.join(overview)}</table></div>{sections}"
        f"<script>{_SCRIPT}</script></body></html>\n")


def write_report(report_dir, comparison, manifest, *, outputs=None, wait=True):
    """Write ``index.html``, ``report.json`` and ``img/*.png`` into ``report_dir``; return it.

    ``outputs`` (:class:`refraster.golden.io.write.Outputs`): stage the report there, to be
    committed with the command's other outputs; ``wait``: wait for another writer's lock."""
    out = Path(report_dir)
    tmp = write.make_tree(write.resolve_target(out, "report directory"))
    try:
        page = _page(tmp, comparison, manifest)
        rio.atomic_write_bytes(tmp / "index.html", page.encode("utf-8"))
        rio.write_json(tmp / "report.json", comparison.to_json())
        write.commit_report(tmp, out, outputs, golden_dir=comparison.golden_dir,
                            candidate_dir=comparison.candidate_dir, wait=wait)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
