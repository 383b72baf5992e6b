"""The ``refraster`` command: render a mesh file, build the gallery, report the set-up.

::

    refraster render MESH_FILE --out image.png [--buffers out.npz] [--width W --height H]
                     [--eye X Y Z] [--target X Y Z] [--fov DEG] [--near N] [--far F]
                     [--cull none|back|front] [--normals flat|smooth]
    refraster gallery --out DIR [--quick] [--jobs N]
    refraster info
    refraster warmup [--jobs N]
    refraster --version

``-q`` silences progress bars and messages; an error is one line on stderr (exit code 2, with
``--debug`` too, which prints the traceback above it). Bad input is rejected before anything is
written; an output path where a FIFO, socket or device is, is refused; ``--out -`` (or
``--buffers -``) writes to standard output.
"""

from __future__ import annotations

import argparse
import html
import os
import struct
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

__all__ = ["main"]

PROG = "refraster"
#: Exit status of every handled error (argparse's own convention for usage errors).
EXIT_ERROR = 2


class CLIError(Exception):
    """An error reported as one line, without a traceback."""


class UsageError(CLIError):
    """Bad command-line usage: one line even with ``--debug``."""


class _Parser(argparse.ArgumentParser):
    # argparse prints the whole usage and exits; we want one line and the same exit code.
    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


def _version():
    from . import __version__
    return __version__


def _common(parser, *, top):
    # The flags work before or after the subcommand; a subparser's default would overwrite the
    # value given before it, so the subparsers' copies default to "not given".
    kw = {} if top else {"default": argparse.SUPPRESS}
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars or messages",
                        **kw)
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors", **kw)


def _build_parser():
    p = _Parser(prog=PROG, description="A CPU reference rasterizer for illustrative rendering.")
    p.add_argument("--version", action="version", version=f"{PROG} {_version()}")
    _common(p, top=True)
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    r = sub.add_parser("render", help="render a mesh file (OBJ, PLY, STL, GLB, OFF, …) to PNG",
                       description="Render a mesh file to a shaded PNG and optionally its "
                                   "G-buffer as .npz. Without --eye the camera frames the mesh.")
    _common(r, top=False)
    r.add_argument("mesh", metavar="MESH_FILE", help="any format trimesh loads")
    r.add_argument("--out", required=True, metavar="IMAGE.png", help="shaded image (PNG)")
    r.add_argument("--buffers", metavar="OUT.npz",
                   help="also write the G-buffer (depth, eye_depth, normal, prim_id, object_id, "
                        "front_facing, barycentric, color)")
    r.add_argument("--width", type=int, default=640)
    r.add_argument("--height", type=int, default=480)
    r.add_argument("--eye", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="camera position (default: framing the mesh's bounding sphere)")
    r.add_argument("--target", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="point looked at (default: the centre of the mesh's bounding box)")
    r.add_argument("--up", type=float, nargs=3, metavar=("X", "Y", "Z"), default=(0.0, 1.0, 0.0))
    r.add_argument("--fov", type=float, default=35.0, help="vertical field of view, degrees")
    r.add_argument("--near", type=float, help="near plane (default: fitted to the mesh)")
    r.add_argument("--far", type=float, help="far plane (default: fitted to the mesh)")
    r.add_argument("--cull", choices=("none", "back", "front"), default="none")
    r.add_argument("--normals", choices=("flat", "smooth"), default="flat")
    r.set_defaults(func=_cmd_render)

    g = sub.add_parser("gallery", help="render every gallery section and write DIR/index.html",
                       description="Render every gallery section to PNGs and write "
                                   "DIR/index.html showing them with captions.")
    _common(g, top=False)
    g.add_argument("--out", required=True, metavar="DIR")
    g.add_argument("--quick", action="store_true", help="small images, light meshes")
    g.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="render the sections in N worker processes of one thread each "
                        "(default: the number of CPUs, at most 2; 1 = in this process)")
    g.set_defaults(func=_cmd_gallery)

    i = sub.add_parser("info", help="versions, threads, kernel cache, llvmpipe oracle",
                       description="Print versions, Numba's thread count and cache directory, "
                                   "and whether the llvmpipe oracle (moderngl + EGL) works.")
    _common(i, top=False)
    i.set_defaults(func=_cmd_info)

    w = sub.add_parser("warmup", help="compile every kernel into the cache ahead of use",
                       description="Compile every kernel the commands use into Numba's cache "
                                   "(for CI images and Docker layers): the pipeline, then the "
                                   "gallery's sections at quick size and the golden scenes, "
                                   "into a temporary directory that is removed.")
    _common(w, top=False)
    w.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="worker processes for the gallery's sections and the golden scenes "
                        "(as 'gallery --jobs', 'golden generate --jobs')")
    w.set_defaults(func=_cmd_warmup)

    from .golden.cli import register as register_golden
    register_golden(sub)
    return p


def _say(args, message):
    if not args.quiet:
        print(message, file=sys.stderr)


def _progress(args, **kw):
    from tqdm import tqdm
    # disable=None: no bar when stderr is not a terminal (logs, CI)
    return tqdm(disable=True if args.quiet else None, file=sys.stderr, leave=False, **kw)


# ---------------------------------------------------------------------------------------------
# render

def _check_output(path, suffix, option):
    """The output path of ``option``: ``-`` (standard output) or a path ending in ``suffix``
    where nothing, a regular file or a link to one is (a FIFO, a socket, a device or a
    directory is refused with one line before anything is rendered or written)."""
    from .golden.io.write import RefusedError, check_regular_output
    if path == "-":
        return path
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise CLIError(f"{option} must name a {suffix} file, got '{path}'")
    try:
        check_regular_output(path, f"{option} '{path}'")
    except RefusedError as exc:
        raise CLIError(str(exc)) from None
    return path


def _load_mesh(path):
    from .mesh import load_mesh_file
    try:
        return load_mesh_file(path)
    except ValueError as exc:
        raise CLIError(_one_line(exc)) from exc


def _check_camera_options(args):
    """Each camera option on its own, so that an error names the option given."""
    import math
    for option, value in (("--eye", args.eye), ("--target", args.target), ("--up", args.up)):
        if value is not None and not all(math.isfinite(v) for v in value):
            raise CLIError(f"{option} must be 3 finite numbers, got "
                           f"{' '.join(str(v) for v in value)}")
    if not 0.0 < args.fov < 180.0:
        raise CLIError(f"--fov must be between 0 and 180 degrees (both excluded), got {args.fov}")
    for option, value in (("--near", args.near), ("--far", args.far)):
        if value is not None and not (math.isfinite(value) and value > 0.0):
            raise CLIError(f"{option} must be a finite number > 0, got {value}")
    if args.up is not None and not any(args.up):
        raise CLIError("--up must not be the zero vector")


#: Largest coordinate trimesh's ``merge_vertices`` holds: it merges on coordinates rounded to
#: 1e-8 as int64, which overflows beyond ~9.2e10 (distinct vertices would then merge).
_MERGE_LIMIT = 1e10


def _merge_vertices(mesh):
    """Share repeated vertices (trimesh's merge; beyond :data:`_MERGE_LIMIT`, or with
    non-finite coordinates, only exact repeats are shared, which needs no rounding)."""
    import numpy as np
    v = np.asarray(mesh.vertices, np.float64)
    if v.size == 0 or (np.all(np.isfinite(v)) and np.abs(v).max() < _MERGE_LIMIT):
        mesh.merge_vertices()
        return
    unique, inverse = np.unique(v, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[np.asarray(mesh.faces)]
    mesh.vertices, mesh.faces = unique, faces


def _camera(args, bounds):
    """View and projection from the options; what is not given frames the mesh's bounds with
    :func:`refraster.camera.frame_bounds` (and is exactly its camera when nothing is given)."""
    import numpy as np
    from .camera import _norm, frame_bounds, look_at, near_far, perspective

    try:
        framed = frame_bounds(bounds, width=args.width, height=args.height, fovy=args.fov,
                              up=args.up)
    except ValueError as exc:
        if str(exc).startswith("fovy="):    # too narrow a field of view to frame the mesh
            raise CLIError(f"--fov {args.fov:g}: {str(exc).split(': ', 1)[-1]}") from None
        raise CLIError(f"mesh file '{args.mesh}': the camera framing it: {exc}") from None
    near, far = near_far(framed.proj)
    view = framed.view
    if args.eye is not None or args.target is not None:
        centre = bounds.mean(axis=0)
        target = np.asarray(args.target if args.target is not None else centre, np.float64)
        if args.eye is not None:
            eye = np.asarray(args.eye, np.float64)
        else:  # frame_bounds' eye, moved with the target: same direction and distance
            eye = np.linalg.inv(framed.view)[:3, 3] + (target - centre)
        view = look_at(eye, target, args.up)
        # enclose the same bounding sphere as frame_bounds (radius × margin 1.1 × 1.05)
        radius = 1.155 * max(0.5 * float(_norm(bounds[1] - bounds[0])), 1e-9)
        with np.errstate(over="ignore"):
            dist = float(_norm(eye - centre))
        near = max(dist - radius, 1e-3 * dist, 1e-6)
        far = max(dist + radius, 2.0 * near)
    if args.near is None and args.far is None and view is framed.view:
        return view, framed.proj
    near = args.near if args.near is not None else near
    far = args.far if args.far is not None else far
    try:
        return view, perspective(args.fov, args.width / args.height, near, far)
    except ValueError as exc:   # a projection beyond float32: name what was given
        given = " ".join(f"{o} {v:g}" for o, v in (("--near", args.near), ("--far", args.far))
                         if v is not None)
        if args.eye is not None and not given:   # near and far fitted to the eye's distance
            given = "--eye " + " ".join(f"{v:g}" for v in args.eye)
        if not given:
            raise CLIError(f"mesh file '{args.mesh}': the camera framing it: {exc}") from None
        raise CLIError(f"{given}: {exc}") from None


def _cmd_render(args):
    import refraster
    from ._validate import as_image_size
    from .golden.io.write import Outputs
    from .io import npz_bytes

    out = _check_output(args.out, ".png", "--out")
    buffers = _check_output(args.buffers, ".npz", "--buffers") if args.buffers else None
    if out == "-" and buffers == "-":
        raise CLIError("--out and --buffers cannot both be '-' (standard output)")
    try:
        as_image_size(args.width, args.height)
    except (TypeError, ValueError) as exc:
        raise CLIError(str(exc)) from exc
    _check_camera_options(args)
    mesh = _load_mesh(args.mesh)
    try:
        view, proj = _camera(args, mesh.bounds)
    except (TypeError, ValueError) as exc:
        raise CLIError(f"camera: {exc}") from exc
    if args.normals == "smooth":
        # STL and other per-face formats repeat vertices; sharing them makes normals smooth.
        # Merging renumbers vertices only, so face (primitive) ids keep the file's order.
        _merge_vertices(mesh)
    progress = getattr(args, "compile_progress", None)
    if progress is not None and progress.n:
        # first run, options checked: the quick tier, while a second process compiles the
        # full one into the cache (refraster/_tiers.py); with REFRASTER_TIER=full, compile
        # the pipeline's kernels on a tiny frame first, on both cores
        from . import _tiers
        if _tiers.current() == _tiers.FULL:
            from .warmup import warm_core_split
            warm_core_split((args.normals,), progress=progress)
        else:
            progress.expect(_tiers.compiled_here())
    with _progress(args, total=3, desc="render", unit="step") as bar:
        bar.set_postfix_str(f"{len(mesh.faces):,} faces")
        bar.update(1)
        t0 = time.perf_counter()
        try:
            fb = refraster.render(mesh, view=view, proj=proj, width=args.width,
                                  height=args.height, raster=refraster.RasterState(
                                      cull=args.cull, normals=args.normals))
        except ValueError as exc:   # e.g. clip coordinates that overflow float32
            raise CLIError(f"mesh file '{args.mesh}': {_one_line(exc)}") from exc
        seconds = time.perf_counter() - t0
        bar.update(1)
        # both files or neither: staged first, then renamed together (a failure undoes both)
        # '-': that one goes to standard output once the files are in place
        outputs = Outputs(command="refraster render")
        stdout = None
        try:
            if buffers is not None:
                data = npz_bytes(fb.arrays())
                if buffers == "-":
                    stdout = data
                else:
                    outputs.file(buffers, data)
            data = _png_bytes(fb.color)
            if out == "-":
                stdout = data
            else:
                outputs.file(out, data)
            outputs.commit()
        except BaseException:
            outputs.discard()
            raise
        if stdout is not None:
            sys.stdout.buffer.write(stdout)
            sys.stdout.flush()
        bar.update(1)
    where = {"-": "standard output"}
    from . import _tiers
    if _tiers.state()[0] == _tiers.QUICK:
        _say(args, "render tier: quick (the same bytes, slower frames; a second process puts "
                   "the full tier in the cache for the next runs)")
    _say(args, f"wrote {where.get(out, out)} ({args.width}x{args.height}, "
               f"{len(mesh.faces):,} faces, {int(fb.mask.sum()):,} pixels covered, "
               f"{seconds:.2f} s)" + (f" and {where.get(buffers, buffers)}" if buffers else ""))
    return 0


def _png_bytes(image):
    import io

    import imageio.v3 as iio
    import numpy as np

    from .io import to_uint8
    buf = io.BytesIO()
    iio.imwrite(buf, np.ascontiguousarray(to_uint8(image)), extension=".png")
    return buf.getvalue()


# ---------------------------------------------------------------------------------------------
# gallery

def _png_size(path):
    """(width, height) from a PNG's IHDR chunk."""
    with open(path, "rb") as fh:
        head = fh.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise CLIError(f"gallery file '{path}' is not a PNG")
    return struct.unpack(">II", head[16:24])


_CSS = """
body { font-family: sans-serif; margin: 0; background: #fafafa; color: #222; }
#toc { position: fixed; top: 0; left: 0; bottom: 0; width: 300px; overflow-y: auto;
       box-sizing: border-box; padding: 1em; background: #f0f0f0; border-right: 1px solid #ddd;
       font-size: .85em; }
#toc h2 { font-size: 1.1em; margin: 0 0 .5em; }
#toc ol { padding-left: 1.2em; margin: 0; } #toc li { margin-bottom: .6em; }
#toc .figs { display: block; margin-top: .2em; line-height: 1.5; }
#toc .figs a { margin-right: .5em; white-space: nowrap; }
main { margin-left: 300px; padding: 1em 1.5em; }
h1 { font-size: 1.5em; margin: 0 0 .3em; } h2 { font-size: 1.2em; margin: 1.6em 0 .2em; }
.paper { font-style: italic; margin: 0 0 .8em; font-size: .9em; }
.grid { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
figure { margin: 0; background: #fff; border: 1px solid #ddd; padding: .5em; max-width: 100%;
         box-sizing: border-box; }
figure.headline { border: 2px solid #6a8; }
figcaption { font-size: .85em; max-width: 40em; margin-top: .3em; }
.fig { font-weight: bold; }
img { display: block; max-width: 100%; height: auto; }
.failed { color: #a00; }
"""

#: "Fig. 10(a)", "Fig. 1/10", "Fig. 4 and 6", "Sec. 5.3" in a caption.
_FIGURE = None


def _figure_label(caption):
    """The paper's figure (or section) a caption names first, e.g. ``Fig. 10(a)``; "" if none."""
    import re
    global _FIGURE
    if _FIGURE is None:
        _FIGURE = (re.compile(r"\b(Figs?\.\s*\d+(?:\s*\([a-z]\))?"
                              r"(?:\s*(?:/|and|–|-)\s*\d+)?)"),
                   re.compile(r"\b(Sec\.\s*\d+(?:\.\d+)*)"))
    for pattern in _FIGURE:
        m = pattern.search(caption)
        if m:
            return " ".join(m.group(1).split())
    return ""


def _page_sections(sections):
    """``sections`` (``(title, items, error)`` in render order) as ``(name, title, items,
    error)`` in page order: the papers' sections first (:data:`refraster.gallery.PAGE_ORDER`),
    each with its headline picture first; sections the gallery does not know, then the plain
    G-buffer section, last."""
    from .gallery import PAGE_ORDER, PAPERS, SECTIONS
    names = {title: name for name, title in SECTIONS}
    named = [(names.get(title, ""), title, list(items), error)
             for title, items, error in sections]
    rank = {name: k for k, name in enumerate(PAGE_ORDER)}
    last = rank.get("basic", len(PAGE_ORDER))
    named.sort(key=lambda s: rank.get(s[0], last - 0.5))
    out = []
    for name, title, items, error in named:
        head = PAPERS.get(name, {}).get("headline")
        items.sort(key=lambda i: i.filename != head)     # stable: the headline first
        out.append((name, title, items, error))
    return out


def _anchor(text):
    import re
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def gallery_html(sections, out_dir, *, quick=False):
    """The gallery page: ``sections`` is a list of ``(title, items, error)``; images are linked
    relative to ``out_dir`` (where ``index.html`` goes). The papers come first: a table of
    contents by paper and figure on the left, each technique's headline figure first with the
    paper's citation, the plain G-buffer section last. Self-contained: no script, no external
    resource."""
    from . import __version__
    from .gallery import PAPERS
    mode = "quick (small images)" if quick else "full size"
    page = _page_sections(sections)
    toc, body = [], []
    for name, title, items, error in page:
        sid = "s-" + (_anchor(name or title) or "section")
        paper = PAPERS.get(name, {}).get("paper", "")
        links = []
        body.append(f'<section id="{sid}">')
        body.append(f"<h2>{html.escape(title)}</h2>")
        if paper:
            body.append(f'<p class="paper">{html.escape(paper)}</p>')
        if error:
            body.append(f'<p class="failed">This section failed: {html.escape(error)}</p>')
        body.append('<div class="grid">')
        head = PAPERS.get(name, {}).get("headline")
        for k, item in enumerate(items):
            w, h = _png_size(Path(out_dir) / item.filename)
            fid = f"{sid}-{k}"
            src = html.escape(quote(Path(item.filename).as_posix()), quote=True)
            label = _figure_label(item.caption)
            cls = ' class="headline"' if item.filename == head else ""
            fig = f'<span class="fig">{html.escape(label)}:</span> ' if label else ""
            # the first pictures load at once, the rest when scrolled to
            lazy = "" if k < 2 else ' loading="lazy"'
            body.append(f'<figure id="{fid}"{cls}><img src="{src}" width="{w}" height="{h}"'
                        f'{lazy} alt="{html.escape(item.caption, quote=True)}">'
                        f"<figcaption>{fig}{html.escape(item.caption)}</figcaption></figure>")
            if label and label not in [lb for lb, _ in links]:
                links.append((label, fid))
        body.append("</div>")
        body.append("</section>")
        figs = "".join(f'<a href="#{fid}">{html.escape(lb)}</a> ' for lb, fid in links)
        toc.append(f'<li><a href="#{sid}">{html.escape(title)}</a>'
                   + (f'<span class="figs">{figs.strip()}</span>' if figs else "") + "</li>")
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>refraster gallery</title>",
        f"<style>{_CSS}</style>",
        "</head>",
        "<body>",
        '<nav id="toc"><h2>The papers, figure by figure</h2><ol>',
        *toc,
        "</ol></nav>",
        "<main>",
        "<h1>refraster gallery</h1>",
        f"<p>refraster {html.escape(__version__)}, {mode}. The papers' figures reproduced by a "
        "CPU reference rasterizer; each section opens with its headline figure, and captions "
        "name the paper's figure each picture follows. The plain G-buffer is last.</p>",
        *body,
        "</main>",
        "</body>",
        "</html>",
        "",
    ]
    return "\n".join(parts)


def _section_items(out_dir, module, quick):
    return _check_items(out_dir, list(module.render(out_dir, quick=quick)))


def _jobs(args):
    jobs = args.jobs if args.jobs is not None else min(os.cpu_count() or 1, 2)
    if jobs < 1:
        raise CLIError(f"--jobs must be at least 1, got {jobs}")
    return jobs


def _worker_groups(modules, jobs):
    """The sections split into groups for worker processes (:data:`refraster.gallery.
    WORKER_GROUPS`), or None when they must run in this process (one job, or sections that are
    not the gallery's own modules)."""
    from .gallery import SECTIONS, WORKER_GROUPS
    names = [m.__name__.rsplit(".", 1)[-1] for _, m in modules]
    known = {name for name, _ in SECTIONS}
    if jobs < 2 or len(names) < 2 or any(
            n not in known or sys.modules.get(m.__name__) is not m
            for n, (_, m) in zip(names, modules)):
        return None
    groups = [[n for n in g if n in names] for g in WORKER_GROUPS]
    rest = [n for n in names if not any(n in g for g in groups)]
    return [g for g in groups if g] + ([rest] if rest else [])


def _while_the_pipeline_compiles(queue, jobs, clip_side_cold):
    """The worker groups to start on a first run while this process compiles the pipeline's
    kernels, taken off ``queue``: the sections that do not use them (at most ``jobs - 1``
    groups), and — when the clip-surface section is still queued and ``clip_side_cold`` —
    ``warm-clipsurface`` after them: the clip surfaces' kernels that need no pipeline kernel
    (:func:`refraster.warmup.warm_clipsurface_side`). Their section compiles longest (the
    critical path of a first run), so a core that would otherwise idle while the pipeline
    compiles here compiles ~40 % of it ahead, and the section loads those from the cache."""
    from ._workers import cold_start_groups
    from .gallery import WITHOUT_PIPELINE
    return cold_start_groups(queue, jobs, WITHOUT_PIPELINE.__contains__, clip_side_cold,
                             clip_group=lambda g: "clipsurface" in g)


def _render_in_workers(args, out_dir, groups, jobs):
    """``{section name: (items, error)}`` from worker processes of one thread each
    (:mod:`refraster.gallery.worker`, run by :func:`refraster._workers.run_groups`), at most
    ``jobs`` at a time; kernels they compile go to the progress line. On a first run the
    pipeline's kernels are compiled here first, while a worker renders the sections that do
    not need them; the other workers then load them from the cache instead of compiling them
    side by side."""
    from ._workers import run_groups
    from .gallery import Item, merge_parts, warm_plan, work_items
    from .warmup import KERNEL_MODULES, STREAM_KERNELS, cache_state

    cached, total = cache_state(KERNEL_MODULES, only=STREAM_KERNELS)
    if cached == total and _gallery_kernels_cached():
        # warm: nothing to compile; the work balanced over the workers, longest first, the
        # longest section in parts (issue 27)
        groups = warm_plan(work_items([n for g in groups for n in g]), jobs)

    def command(group):
        return [str(out_dir), *group] + (["--quick"] if args.quick else [])

    answers = run_groups("refraster.gallery.worker", groups, jobs, key="section",
                         command=command, progress=getattr(args, "compile_progress", None),
                         cold_start=lambda queue, side_cold: _while_the_pipeline_compiles(
                             queue, jobs, side_cold))
    return merge_parts({name: ([Item(*i) for i in (result or {}).get("items", [])], error)
                        for name, result, error in answers})


def _gallery_kernels_cached():
    """Whether every kernel a gallery run compiles is in the cache (none to compile)."""
    from .warmup import GALLERY_SKIPS, _cached, _name, kernels
    return all(_cached(d) for d in kernels() if _name(d) not in GALLERY_SKIPS)


def _check_items(out_dir, items):
    for item in items:
        name = Path(item.filename)
        if name.is_absolute() or ".." in name.parts:
            raise ValueError(f"item file {item.filename!r} is not relative to the gallery")
        if not (out_dir / name).is_file():
            raise FileNotFoundError(f"item file {item.filename!r} was not written")
    return items


def _cmd_gallery(args):
    from .gallery import section_modules
    from .io import atomic_write_bytes

    out_dir = Path(args.out)
    if out_dir.exists() and not out_dir.is_dir():
        raise CLIError(f"--out '{out_dir}' exists and is not a directory")
    jobs = _jobs(args)
    modules = list(section_modules())
    sections, failures = [], []
    t0 = time.perf_counter()
    groups = _worker_groups(modules, jobs)
    done = {}
    if groups is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        done = _render_in_workers(args, out_dir, groups, jobs)
    with _progress(args, total=len(modules), desc="gallery", unit="section") as bar:
        for title, module in modules:
            name = module.__name__.rsplit(".", 1)[-1]
            bar.set_postfix_str(name)
            try:
                if name in done:
                    items, error = done[name]
                    if error:
                        raise _SectionError(error)
                    sections.append((title, _check_items(out_dir, items), None))
                else:
                    sections.append((title, _section_items(out_dir, module, args.quick), None))
            except Exception as exc:
                if args.debug:
                    raise
                msg = str(exc) if isinstance(exc, _SectionError) else \
                    f"{type(exc).__name__}: {_one_line(exc)}"
                sections.append((title, [], msg))
                failures.append(f"{name} ({msg})")
            bar.update(1)
    page = gallery_html(sections, out_dir, quick=args.quick)
    index = atomic_write_bytes(out_dir / "index.html", page.encode("utf-8"))
    n = sum(len(items) for _, items, _ in sections)
    _say(args, f"wrote {index}: {len(sections)} sections, {n} images, "
               f"{time.perf_counter() - t0:.1f} s")
    if failures:
        raise CLIError(f"{len(failures)} gallery section(s) failed: " + "; ".join(failures))
    return 0


class _SectionError(Exception):
    """A section's failure reported by a worker process (already one line)."""


# ---------------------------------------------------------------------------------------------
# warmup

def _cmd_warmup(args):
    import tempfile

    from .warmup import cache_state, warm_core
    t0 = time.perf_counter()
    warm_core(clip=True, stream=True, reusable=True, multisample=True)
    with tempfile.TemporaryDirectory(prefix="refraster-warmup-") as tmp:
        sub = argparse.Namespace(**{**vars(args), "out": str(Path(tmp) / "gallery"),
                                    "quick": True, "quiet": True})
        sub.compile_progress = getattr(args, "compile_progress", None)
        _cmd_gallery(sub)
        gen = _build_parser().parse_args(["golden", "generate", "-q", "--jobs",
                                          str(_jobs(args)), "--out", str(Path(tmp) / "golden")])
        gen.compile_progress = sub.compile_progress   # its workers' kernels on the line too
        gen.func(gen)
    cached, total = cache_state()
    _say(args, f"warmup: {cached} of {total} kernels in the cache "
               f"({time.perf_counter() - t0:.1f} s)")
    return 0


# ---------------------------------------------------------------------------------------------
# info

_EGL_PROBE = (
    "import moderngl\n"
    "ctx = moderngl.create_standalone_context(backend='egl')\n"
    "print(ctx.info['GL_RENDERER'])\n"
)


def llvmpipe_status(timeout=30.0):
    """``(available, detail)``: whether moderngl gets an EGL context, probed in a subprocess so
    that a broken driver can neither hang nor crash the caller."""
    try:
        proc = subprocess.run([sys.executable, "-c", _EGL_PROBE], capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return False, f"the EGL probe did not answer within {timeout:.0f} s"
    if proc.returncode != 0:
        lines = [ln for ln in (proc.stderr or "").strip().splitlines() if ln.strip()]
        return False, (lines[-1] if lines else f"the EGL probe exited with {proc.returncode}")
    renderer = proc.stdout.strip()
    return "llvmpipe" in renderer.lower(), renderer


def kernel_cache():
    """``(directory, how)``: where Numba keeps refraster's compiled kernels."""
    import numba
    configured = numba.config.CACHE_DIR
    if configured:
        return os.path.abspath(configured), "NUMBA_CACHE_DIR"
    from .raster import rasterizer
    package = Path(rasterizer.__file__).resolve().parents[1]
    # Numba's default is a __pycache__ beside each module, or a user-wide directory when the
    # package is not writable; the cache locator of a real kernel says which one applies.
    disp = next((v for v in vars(rasterizer).values()
                 if hasattr(getattr(v, "_cache", None), "_cache_path")), None)
    path = Path(disp._cache._cache_path if disp is not None
                else Path(rasterizer.__file__).parent / "__pycache__")
    if path.resolve().is_relative_to(package):
        return str(path), "Numba default: __pycache__ beside each module"
    return str(path), "Numba default: user-wide cache (the package is not writable)"


def _cmd_info(args):
    import numba
    import numpy as np

    def version_of(name):
        try:
            from importlib.metadata import version
            return version(name)
        except Exception:
            return "not installed"

    cache, how = kernel_cache()
    from .warmup import cache_state
    cached, total = cache_state()
    state = ("warm" if cached == total else "cold" if cached == 0 else "partly warm")
    warmth = f"{state}: {cached} of {total} kernels compiled and cached"
    if cached == 0:
        warmth += f"; the first run compiles the rest (minutes), '{PROG} warmup' does it ahead"
    elif cached < total:
        warmth += ("; the others compile on first use (options the gallery and the goldens "
                   f"do not use, or sources changed since; '{PROG} warmup' compiles the rest "
                   "of what they use)")
    ok, detail = llvmpipe_status()
    rows = [
        ("refraster", _version()),
        ("python", sys.version.split()[0]),
        ("numpy", np.__version__),
        ("numba", numba.__version__),
        ("trimesh", version_of("trimesh")),
        ("manifold3d", version_of("manifold3d")),
        ("numba threads", f"{numba.config.NUMBA_NUM_THREADS} (NUMBA_NUM_THREADS"
                          f"{'' if 'NUMBA_NUM_THREADS' in os.environ else ' default: CPU count'})"),
        ("kernel cache", f"{cache} [{how}]"),
        ("kernels", warmth),
        ("fast compile", _compile_speed_state()),
        ("render tier", _tier_state()),
        ("output pool", _pool_state()),
        ("llvmpipe oracle", f"{'available' if ok else 'not available'} ({detail})"),
    ]
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key + ':':<{width + 1}} {value}")
    return 0


def _pool_state():
    from ._scratch import _pool_limit
    limit = _pool_limit()
    if limit <= 0:
        return "off (REFRASTER_POOL_MB=0: every frame's outputs are new arrays)"
    return (f"up to {limit / (1 << 20):g} MiB of dropped frames' outputs recycled "
            "(REFRASTER_POOL_MB; 0 turns it off)")


def _tier_state():
    """Which tier of the render kernels a ``render`` runs (refraster/_tiers.py)."""
    from . import _tiers
    tier, why = _tiers.preview()
    if tier == _tiers.FULL:
        return f"full ({why}; REFRASTER_TIER=auto|full|quick)"
    return (f"quick: serial, helpers not inlined, the same bytes, slower frames ({why}; "
            "REFRASTER_TIER=auto|full|quick)")


def _compile_speed_state():
    from . import _compile_speed
    on, reason = _compile_speed.state()
    if on:
        return "on (Numba's copy propagation, same machine code; REFRASTER_COMPILE_SPEEDUP=0 turns it off)"
    return reason


# ---------------------------------------------------------------------------------------------

def _compile_progress(args):
    """The progress line of the kernels a command compiles on its first run
    (:class:`refraster.warmup.CompileProgress`), or a no-op for commands that compile none."""
    import contextlib
    command = args.command
    if command == "golden" and getattr(args, "golden_command", None) == "generate" and not \
            getattr(args, "list", False):
        command = "golden generate"
    if command not in ("render", "gallery", "golden generate", "warmup"):
        return contextlib.nullcontext()
    from .warmup import (CORE_MODULES, GALLERY_SKIPS, KERNEL_MODULES, RENDER_KERNELS,
                         CompileProgress)
    if command == "render":
        return CompileProgress(CORE_MODULES, only=RENDER_KERNELS, quiet=args.quiet)
    return CompileProgress(KERNEL_MODULES, skip=GALLERY_SKIPS if command == "gallery" else (),
                           quiet=args.quiet)


def _batch_runs_full_tier(args):
    """``gallery``, ``golden generate`` and ``warmup`` compile ahead and render many frames:
    the full tier of the render kernels (refraster/_tiers.py), unless ``REFRASTER_TIER`` says
    otherwise (their workers get the same, refraster/_workers.py)."""
    from . import _tiers
    if args.command in ("gallery", "golden", "warmup") and _tiers._setting() == "auto":
        _tiers.force(_tiers.FULL)


def _one_line(exc):
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def main(argv=None):
    """Run the command line; return the exit status (0 success, 2 error)."""
    from .golden.io.write import Terminated, terminate_as_interrupt
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in argv
    try:
        with terminate_as_interrupt():  # SIGTERM cleans up like Ctrl-C
            args = _build_parser().parse_args(argv)
            if args.command is None:
                raise UsageError("a command is required: render, gallery, info, warmup or golden "
                                 f"(see '{PROG} --help')")
            from ._logs import one_line_logs
            with one_line_logs(PROG, debug=getattr(args, "debug", debug),
                               quiet=getattr(args, "quiet", False)):
                _batch_runs_full_tier(args)
                with _compile_progress(args) as progress:
                    args.compile_progress = progress
                    return args.func(args)
    except KeyboardInterrupt as exc:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130
    except Exception as exc:
        if debug and not isinstance(exc, UsageError):   # the traceback, then the same line
            import traceback
            traceback.print_exception(exc, file=sys.stderr)
        name = type(exc).__name__
        if name.lower() == "error":                     # struct.error: never "error: error:"
            name = f"{type(exc).__module__}.{name}"
        what = "" if isinstance(exc, CLIError) else f"{name}: "
        text = _one_line(exc)
        if isinstance(exc, MemoryError):
            what, text = "", f"out of memory ({type(exc).__name__}" + (
                f": {text})" if str(exc).strip() else ")")
        print(f"{PROG}: error: {what}{text}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
