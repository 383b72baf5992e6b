"""The ``refraster`` command: render a mesh file, build the gallery, report the set-up.

::

    refraster render MESH_FILE --out image.png [--buffers out.npz] [--width W --height H]
                     [--eye X Y Z] [--target X Y Z] [--fov DEG] [--near N] [--far F]
                     [--cull none|back|front] [--normals flat|smooth]
    refraster gallery --out DIR [--quick]
    refraster info
    refraster --version

``-q`` silences progress bars and messages; an error is one line on stderr (exit code 2) and
shows a traceback only with ``--debug``. Bad input is rejected before anything is written.
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
    g.set_defaults(func=_cmd_gallery)

    i = sub.add_parser("info", help="versions, threads, kernel cache, llvmpipe oracle",
                       description="Print versions, Numba's thread count and cache directory, "
                                   "and whether the llvmpipe oracle (moderngl + EGL) works.")
    _common(i, top=False)
    i.set_defaults(func=_cmd_info)

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
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise CLIError(f"{option} must name a {suffix} file, got '{path}'")
    if path.is_dir():
        raise CLIError(f"{option} '{path}' is a directory")
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


def _camera(args, bounds):
    """View and projection from the options; what is not given frames the mesh's bounds with
    :func:`refraster.camera.frame_bounds` (and is exactly its camera when nothing is given)."""
    import numpy as np
    from .camera import frame_bounds, look_at, near_far, perspective

    framed = frame_bounds(bounds, width=args.width, height=args.height, fovy=args.fov,
                          up=args.up)
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
        radius = 1.155 * max(0.5 * float(np.linalg.norm(bounds[1] - bounds[0])), 1e-9)
        dist = float(np.linalg.norm(eye - centre))
        near = max(dist - radius, 1e-3 * dist, 1e-6)
        far = max(dist + radius, 2.0 * near)
    if args.near is None and args.far is None and view is framed.view:
        return view, framed.proj
    near = args.near if args.near is not None else near
    far = args.far if args.far is not None else far
    return view, perspective(args.fov, args.width / args.height, near, far)


def _cmd_render(args):
    import refraster
    from ._validate import as_image_size
    from .golden.write import Outputs
    from .io import npz_bytes

    out = _check_output(args.out, ".png", "--out")
    buffers = _check_output(args.buffers, ".npz", "--buffers") if args.buffers else None
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
        mesh.merge_vertices()
    with _progress(args, total=3, desc="render", unit="step") as bar:
        bar.set_postfix_str(f"{len(mesh.faces):,} faces")
        bar.update(1)
        t0 = time.perf_counter()
        try:
            fb = refraster.render(mesh, view=view, proj=proj, width=args.width,
                                  height=args.height, cull=args.cull, normals=args.normals)
        except ValueError as exc:   # e.g. clip coordinates that overflow float32
            raise CLIError(f"mesh file '{args.mesh}': {_one_line(exc)}") from exc
        seconds = time.perf_counter() - t0
        bar.update(1)
        # both files or neither: staged first, then renamed together (a failure undoes both)
        outputs = Outputs(command="refraster render")
        try:
            if buffers is not None:
                outputs.file(buffers, npz_bytes(fb.arrays()))
            outputs.file(out, _png_bytes(fb.color))
            outputs.commit()
        except BaseException:
            outputs.discard()
            raise
        bar.update(1)
    _say(args, f"wrote {out} ({args.width}x{args.height}, {len(mesh.faces):,} faces, "
               f"{int(fb.mask.sum()):,} pixels covered, {seconds:.2f} s)"
               + (f" and {buffers}" if buffers else ""))
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
body { font-family: sans-serif; margin: 1.5em; background: #fafafa; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 2em; }
.grid { display: flex; flex-wrap: wrap; gap: 1em; }
figure { margin: 0; background: #fff; border: 1px solid #ddd; padding: .5em; }
figcaption { font-size: .85em; max-width: 32em; margin-top: .3em; }
img { display: block; image-rendering: pixelated; }
.failed { color: #a00; }
"""


def gallery_html(sections, out_dir, *, quick=False):
    """The gallery page: ``sections`` is a list of ``(title, items, error)``; images are linked
    relative to ``out_dir`` (where ``index.html`` goes). Self-contained: no script, no external
    resource."""
    from . import __version__
    mode = "quick (small images)" if quick else "full size"
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
        "<h1>refraster gallery</h1>",
        f"<p>refraster {html.escape(__version__)}, {mode}. Every picture is a CPU reference "
        "rendering; captions say what each shows.</p>",
    ]
    for title, items, error in sections:
        parts.append(f"<h2>{html.escape(title)}</h2>")
        if error:
            parts.append(f'<p class="failed">This section failed: {html.escape(error)}</p>')
        parts.append('<div class="grid">')
        for item in items:
            w, h = _png_size(Path(out_dir) / item.filename)
            src = html.escape(quote(Path(item.filename).as_posix()), quote=True)
            cap = html.escape(item.caption)
            parts.append(f'<figure><img src="{src}" width="{w}" height="{h}" '
                         f'alt="{html.escape(item.caption, quote=True)}">'
                         f"<figcaption>{cap}</figcaption></figure>")
        parts.append("</div>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


def _section_items(out_dir, module, quick):
    items = list(module.render(out_dir, quick=quick))
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
    modules = list(section_modules())
    sections, failures = [], []
    t0 = time.perf_counter()
    with _progress(args, total=len(modules), desc="gallery", unit="section") as bar:
        for title, module in modules:
            bar.set_postfix_str(module.__name__.rsplit(".", 1)[-1])
            try:
                sections.append((title, _section_items(out_dir, module, args.quick), None))
            except Exception as exc:
                if args.debug:
                    raise
                msg = f"{type(exc).__name__}: {_one_line(exc)}"
                sections.append((title, [], msg))
                failures.append(f"{module.__name__.rsplit('.', 1)[-1]} ({msg})")
            bar.update(1)
    page = gallery_html(sections, out_dir, quick=args.quick)
    index = atomic_write_bytes(out_dir / "index.html", page.encode("utf-8"))
    n = sum(len(items) for _, items, _ in sections)
    _say(args, f"wrote {index}: {len(sections)} sections, {n} images, "
               f"{time.perf_counter() - t0:.1f} s")
    if failures:
        raise CLIError(f"{len(failures)} gallery section(s) failed: " + "; ".join(failures))
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
        ("llvmpipe oracle", f"{'available' if ok else 'not available'} ({detail})"),
    ]
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key + ':':<{width + 1}} {value}")
    return 0


# ---------------------------------------------------------------------------------------------

def _one_line(exc):
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def main(argv=None):
    """Run the command line; return the exit status (0 success, 2 error)."""
    from .golden.write import Terminated, terminate_as_interrupt
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in argv
    try:
        with terminate_as_interrupt():  # SIGTERM cleans up like Ctrl-C
            args = _build_parser().parse_args(argv)
            if args.command is None:
                raise UsageError("a command is required: render, gallery, info or golden "
                                 f"(see '{PROG} --help')")
            from ._logs import one_line_logs
            with one_line_logs(PROG, debug=getattr(args, "debug", debug),
                               quiet=getattr(args, "quiet", False)):
                return args.func(args)
    except KeyboardInterrupt as exc:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130
    except Exception as exc:
        if debug and not isinstance(exc, UsageError):
            raise
        what = "" if isinstance(exc, CLIError) else f"{type(exc).__name__}: "
        text = _one_line(exc)
        if isinstance(exc, MemoryError):
            what, text = "", f"out of memory ({type(exc).__name__}" + (
                f": {text})" if str(exc).strip() else ")")
        print(f"{PROG}: error: {what}{text}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
