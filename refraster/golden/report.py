"""The HTML report of a comparison: per scene and buffer, reference, candidate, difference,
error mask and FLIP map side by side, with the metrics and checks.

The report is a static page (no script) with PNGs beside it in ``img/``; it is built in a
temporary sibling directory and committed by :mod:`refraster.golden.write` (locked, atomic,
replacing only a report refraster wrote), like a golden.
"""

from __future__ import annotations

import html
import math
import shutil
from pathlib import Path

import numpy as np

from .. import io as rio
from .buffers import preview, preview_range
from . import write

__all__ = ["write_report", "check_report_dir", "difference_image", "mask_image"]

_CSS = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; }
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 2em; }
.pass { color: #176b2c; } .fail { color: #b3261e; } .error { color: #8a4b00; }
table.metrics { border-collapse: collapse; margin: .4em 0; }
table.metrics td, table.metrics th { border: 1px solid #ccc; padding: 2px 8px; text-align: right; }
.row { display: flex; gap: 12px; flex-wrap: wrap; align-items: flex-start; }
figure { margin: 0; } figcaption { font-size: 12px; color: #555; text-align: center; }
img { image-rendering: pixelated; border: 1px solid #999; background: #fff; }
.na { display: inline-block; border: 1px dashed #bbb; color: #888; text-align: center; }
.buffer { border-top: 1px solid #ddd; padding: .6em 0; }
code { background: #f3f3f3; padding: 0 3px; }
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
    (:func:`refraster.golden.write.check_report_dir`)."""
    return write.check_report_dir(report, golden_dir, candidate_dir)


def _fmt(x):
    if x is None:
        return "—"
    if isinstance(x, float):
        return str(x) if not math.isfinite(x) else f"{x:.4g}"
    return html.escape(str(x))


def _figure(src, caption, width, height, zoom):
    if src is None:
        return (f'<figure><span class="na" style="width:{width * zoom}px;'
                f'height:{height * zoom}px;line-height:{height * zoom}px">n/a</span>'
                f"<figcaption>{caption}</figcaption></figure>")
    return (f'<figure><img src="{html.escape(src)}" width="{width * zoom}" '
            f'height="{height * zoom}" alt="{html.escape(caption)}">'
            f"<figcaption>{caption}</figcaption></figure>")


def _buffer_html(root, scene, b):
    h, w = b.reference.shape[:2]
    zoom = 2 if w <= 128 else 1
    vr = preview_range(b.reference, b.kind)
    ref_png = preview(b.reference, b.kind, vr)
    stem = f"img/{scene}__{b.name}"
    rio.write_png(root / f"{stem}__reference.png", ref_png)
    rio.write_png(root / f"{stem}__candidate.png", preview(b.candidate, b.kind, vr))
    rio.write_png(root / f"{stem}__difference.png", difference_image(b.images["error"]))
    rio.write_png(root / f"{stem}__mask.png",
                  mask_image(ref_png, b.images["over"], b.images["forgiven"],
                             b.images.get("may")))
    flip = None
    if b.images["flip"] is not None:
        flip = f"{stem}__flip.png"
        rio.write_png(root / flip, b.images["flip"])
    m = b.metrics
    status = "pass" if b.passed else "fail"
    rows = "".join(
        f"<tr><td>{html.escape(c['metric'])}</td><td>{_fmt(c['value'])}</td>"
        f"<td>{html.escape(c['op'])} {_fmt(c['limit'])}</td>"
        f"<td class=\"{'pass' if c['ok'] else 'fail'}\">{'ok' if c['ok'] else 'FAIL'}</td></tr>"
        for c in b.checks)
    figures = "".join([
        _figure(f"{stem}__reference.png", "reference", w, h, zoom),
        _figure(f"{stem}__candidate.png", "candidate", w, h, zoom),
        _figure(f"{stem}__difference.png", f"difference (max {_fmt(m['max_abs'])})", w, h, zoom),
        _figure(f"{stem}__mask.png",
                "error mask: red outside the allowance, yellow allowed, blue may-region"
                if "may" in b.images else "error mask: red fails, yellow forgiven", w, h, zoom),
        _figure(flip, "FLIP" + (f" (mean {_fmt(m.get('flip_mean'))})" if flip else ""),
                w, h, zoom),
    ])
    return (
        f'<div class="buffer"><h3>{html.escape(b.name)} <small>({html.escape(b.kind)}, from '
        f'<code>{html.escape(b.source)}</code>)</small> <span class="{status}">'
        f"{status.upper()}</span></h3>"
        f'<table class="metrics"><tr><th>max abs</th><th>RMSE</th><th>PSNR</th><th>threshold</th>'
        f"<th>over</th><th>unforgiven</th><th>radius</th><th>FLIP</th></tr><tr>"
        f"<td>{_fmt(m['max_abs'])}</td><td>{_fmt(m['rmse'])}</td><td>{_fmt(m['psnr'])}</td>"
        f"<td>{_fmt(m['threshold'])}</td><td>{m['n_over']} ({_fmt(m['fraction_over'])})</td>"
        f"<td>{m['n_unforgiven']} ({_fmt(m['fraction_unforgiven'])})</td>"
        f"<td>{b.tolerance['deviation_radius']}</td><td>{_fmt(m.get('flip_mean'))}</td></tr>"
        f'</table><table class="metrics"><tr><th>check</th><th>value</th><th>limit</th>'
        f"<th></th></tr>{rows}</table>"
        f'<div class="row">{figures}</div></div>')


def write_report(report_dir, comparison, manifest, *, outputs=None, wait=True):
    """Write ``index.html``, ``report.json`` and ``img/*.png`` into ``report_dir``; return it.

    ``outputs`` (:class:`refraster.golden.write.Outputs`): stage the report there, to be
    committed with the command's other outputs; ``wait``: wait for another writer's lock."""
    out = Path(report_dir)
    tmp = write.make_tree(write.resolve_target(out, "report directory"))
    try:
        verdict = ["PASS", "FAIL", "UNUSABLE INPUT"][comparison.exit_code]
        verdict_class = ["pass", "fail", "error"][comparison.exit_code]
        overview = []
        for s in comparison.scenes:
            failing = ", ".join(f"{b.name}: {m}" for b in s.buffers for m in b.failed_metrics)
            overview.append(
                f'<tr><td><a href="#{html.escape(s.name)}">{html.escape(s.name)}</a></td>'
                f'<td class="{s.status}">{s.status.upper()}</td>'
                f"<td>{html.escape(failing or s.error or '')}</td></tr>")
        overview = "".join(overview)
        sections = []
        for s in comparison.scenes:
            entry = manifest["scenes"][s.name]
            body = (f'<p class="error">Unusable candidate: {html.escape(s.error)}</p>'
                    if s.error else "".join(_buffer_html(tmp, s.name, b) for b in s.buffers))
            sections.append(
                f'<h2 id="{html.escape(s.name)}">{html.escape(s.name)} '
                f'<span class="{s.status}">{s.status.upper()}</span></h2>'
                f"<p>{html.escape(entry['description'])} Technique "
                f"<code>{html.escape(entry['technique'])}</code>.</p>{body}")
        gen = manifest["generator"]
        page = (
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<link rel=\"icon\" href=\"data:,\">"
            f"<title>refraster golden compare: {verdict}</title><style>{_CSS}</style></head>"
            f"<body><h1>Golden compare: <span class=\"{verdict_class}\">{verdict}</span></h1>"
            f"<p>Golden <code>{html.escape(str(comparison.golden_dir))}</code> (refraster "
            f"{html.escape(gen['refraster'])}, numpy {html.escape(gen['numpy'])}, numba "
            f"{html.escape(gen['numba'])}; {manifest['raster']['subpixel_bits']} sub-pixel bits, "
            f"fill rule {html.escape(manifest['raster']['fill_rule'])}) against candidate "
            f"<code>{html.escape(str(comparison.candidate_dir))}</code>, tolerance profile "
            f"<code>{html.escape(comparison.profile)}</code>.</p>"
            f'<table class="metrics"><tr><th>scene</th><th>status</th><th>failing</th></tr>'
            f"{overview}</table>{''.join(sections)}</body></html>\n")
        rio.atomic_write_bytes(tmp / "index.html", page.encode("utf-8"))
        rio.write_json(tmp / "report.json", comparison.to_json())
        write.commit_report(tmp, out, outputs, golden_dir=comparison.golden_dir,
                            candidate_dir=comparison.candidate_dir, wait=wait)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
