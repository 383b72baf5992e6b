"""``golden generate`` and ``golden compare`` on the command line.

::

    refraster golden generate --out DIR [--scene NAME ...] [--scene-file SCENE.toml ...]
                              [--update] [--list] [--sweep KEY=V1,V2 ...] [--size WxH ...]
                              [--jobs N | --workers N | --scheduler ADDRESS]
                              [--convention gl|vulkan|d3d12|metal|webgpu] [--no-wait]
                              [--candidate-subpixel-bits N]
    refraster golden compare GOLDEN_DIR CANDIDATE_DIR [--report DIR] [--mode tolerant|exact]
                             [--profile exact|conformant] [--tolerance [SCENE:][BUFFER.]KEY=VALUE ...]
                             [--scene NAME ...] [--json FILE] [--no-wait]
    refraster golden candidate GOLDEN_DIR --backend gl|wgpu --out CANDIDATE_DIR [--scene NAME ...]
                               [--threads N] [--no-wait]

``-q``/``--quiet`` and ``--debug`` go before or after ``golden``, ``generate`` or ``compare``.

``compare`` is tolerant by default when the golden stores allowances (coverage masks and value
intervals), bit-exact otherwise; ``--profile`` alone selects a metric profile as before.

Exit status: 0 pass (or generated), 1 a comparison failed, 2 unusable input (bad arguments, a
golden that cannot be read, a candidate file missing, corrupt or of the wrong shape). The
``refraster`` command adds these with :func:`register`; ``python -m refraster.golden.cli`` runs
them alone (:func:`main`).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys

from .io.errors import EXIT_PASS, EXIT_UNUSABLE, GoldenError
from .compare.run import MODES
from .compare.profiles import PROFILES

__all__ = ["register", "main"]


def _error(args, prog, exc, *, usage=False):
    """One line on stderr and exit status 2; ``--debug`` prints the traceback above it (not for
    usage errors) and keeps the status."""
    if getattr(args, "debug", False) and not usage:
        import traceback
        traceback.print_exception(exc, file=sys.stderr)
    print(f"{prog}: error: {error_text(exc)}", file=sys.stderr)
    return EXIT_UNUSABLE


def error_text(exc):
    """The one line an exception is reported as: its message on one line, after its class name
    unless it is a ``ValueError`` or an ``OSError`` (whose messages name the cause); a class
    named ``error`` (``struct.error``, ``re.error``) by its module, never "error: error:"."""
    text = " ".join(str(exc).split())
    if isinstance(exc, MemoryError):
        return f"out of memory ({type(exc).__name__}{': ' + text if text else ''})"
    name = type(exc).__name__
    if name.lower() == "error":
        name = f"{type(exc).__module__}.{name}"
    if not isinstance(exc, (ValueError, OSError)):
        return f"{name}: {text}" if text else name
    return text or name


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return value


def _candidate_bits(text):
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 4 <= value <= 8:
        raise argparse.ArgumentTypeError(f"must be an integer from 4 to 8 (the sub-pixel bits "
                                         f"a conformant candidate may use), got {text!r}")
    return value


def _common(parser):
    # after the subcommand too; SUPPRESS keeps a value given before it
    parser.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                        help="no progress bars or messages")
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show tracebacks on errors (not on usage errors)")


def _guarded(prog):
    """Every failure of the command is one line and exit 2 (a traceback only with --debug);
    log records of any library become one-line warnings (:mod:`refraster._logs`)."""
    def wrap(fn):
        @functools.wraps(fn)
        def run(args):
            from .._logs import one_line_logs
            with one_line_logs("refraster", debug=getattr(args, "debug", False),
                               quiet=getattr(args, "quiet", False)):
                try:
                    return fn(args)
                except KeyboardInterrupt as exc:
                    from .io.write import Terminated
                    print(f"{prog}: interrupted", file=sys.stderr)
                    return 143 if isinstance(exc, Terminated) else 130
                except Exception as exc:
                    return _error(args, prog, exc)
        return run
    return wrap


def _say(args, message):
    if not getattr(args, "quiet", False):
        print(message, file=sys.stderr)


def _in_convention(api, names, scene_files):
    """The scenes of ``generate --convention API``: the named ones (or, without ``--scene``,
    every single-sample scene whose technique honours the conventions, for ``gl`` too: a scene of
    another technique may be in other conventions already, ``reversed_z_peel``) and the TOML
    scenes, each
    drawn in ``api``'s conventions (:func:`refraster.golden.conventions.in_convention`)."""
    from .conventions import TECHNIQUES_IN_CONVENTIONS, in_convention
    from .scenes import available_scenes, load_scene_file
    registry = available_scenes()
    if names is None:
        names = [] if scene_files else [
            n for n, e in registry.items()
            if e.technique in TECHNIQUES_IN_CONVENTIONS and e.samples == 1]
    unknown = [n for n in names if n not in registry]
    if unknown:
        raise ValueError(f"unknown golden scene(s) {unknown}; known: {sorted(registry)}")
    entries = [registry[n] for n in names] + [load_scene_file(p) for p in scene_files]
    return [in_convention(e, api) for e in entries]


@_guarded("golden generate")
def _cmd_generate(args):
    from .generate import generate
    from .scenes import available_scenes
    if args.list:
        for name, entry in available_scenes().items():
            print(f"{name:<28} {entry.technique:<12} {entry.description}")
        return EXIT_PASS
    if args.out is None:
        return _error(args, "golden generate", ValueError("--out DIR is required"), usage=True)
    from .generate import GenerationError
    if args.workers is not None and args.scheduler is not None:
        return _error(args, "golden generate",
                      ValueError("--workers and --scheduler exclude each other"), usage=True)
    if args.jobs is not None and (args.workers is not None or args.scheduler is not None):
        return _error(args, "golden generate",
                      ValueError("--jobs excludes --workers and --scheduler"), usage=True)
    import os
    jobs = args.jobs if args.jobs is not None else (
        1 if args.workers is not None or args.scheduler is not None
        else min(os.cpu_count() or 1, 2))
    quiet = getattr(args, "quiet", False)
    retried = []

    def on_retry(name, reason):
        retried.append(name)
        _say(args, f"retrying {name} once: {reason}")

    scenes, scene_files = args.scene or None, args.scene_file or ()
    if args.convention is not None:
        try:
            scenes, scene_files = _in_convention(args.convention, scenes, scene_files), ()
        except ValueError as exc:
            return _error(args, "golden generate", exc)
    try:
        manifest = generate(args.out, scenes, update=args.update,
                            scene_files=scene_files, sweeps=args.sweep or (),
                            sizes=args.size or (), workers=args.workers or 1,
                            scheduler=args.scheduler, progress_bar=not quiet,
                            on_retry=on_retry,
                            wait=False if args.no_wait else (
                                lambda holder: _say(args, f"waiting for {holder} to finish "
                                                          f"writing {args.out}")),
                            jobs=jobs, compile_progress=getattr(args, "compile_progress", None),
                            candidate_subpixel_bits=args.candidate_subpixel_bits)
    except (ValueError, TypeError, OSError, GenerationError) as exc:
        return _error(args, "golden generate", exc)
    if retried:
        _say(args, f"{len(retried)} scene(s) were retried once and then succeeded: "
                   f"{', '.join(retried)}")
    _say(args, f"wrote {len(manifest['scenes'])} scene(s) and {len(manifest['files'])} files "
               f"to {args.out}")
    return EXIT_PASS


@_guarded("golden compare")
def _cmd_compare(args):
    from .io import write
    from .compare.run import compare
    from .compare.run import has_allowances, load_manifest
    try:
        # compare only reads the golden: a journal beside it is never acted on
        write.pending_swap(args.golden_dir)
    except (GoldenError, OSError) as exc:
        return _error(args, "golden compare", exc)
    mode = args.mode
    if mode is None and args.profile is None:
        # tolerant by default once the golden stores allowances
        try:
            manifest = load_manifest(args.golden_dir, verify=False)
            names = [n for n in (args.scene or manifest["scenes"]) if n in manifest["scenes"]]
            mode = "tolerant" if names and has_allowances(manifest, names) else "exact"
        except GoldenError:
            mode = "exact"   # compare reports what is wrong with the golden
    # every output is staged, then all are committed together (or none)
    outputs = write.Outputs(wait=not args.no_wait, command="refraster golden compare")
    to_stdout = args.json == "-"
    try:
        if args.json is not None and not to_stdout:
            write.check_regular_output(args.json, f"--json {args.json}")
            write.check_output_path(args.json, "--json", {
                "golden directory": args.golden_dir, "candidate directory": args.candidate_dir,
                "report directory": args.report})
        result = compare(args.golden_dir, args.candidate_dir, report=args.report,
                         profile=args.profile, mode=mode, tolerances=args.tolerance or (),
                         scenes=args.scene or None, outputs=outputs)
        text = None
        if args.json is not None:
            text = json.dumps(result.to_json(), indent=2, sort_keys=True) + "\n"
            if not to_stdout:
                outputs.file(args.json, text.encode("utf-8"))
        outputs.commit()
        if to_stdout:     # standard output holds the JSON alone; the summary goes to stderr
            sys.stdout.write(text)
            sys.stdout.flush()
    except (GoldenError, ValueError, OSError) as exc:
        outputs.discard()
        return _error(args, "golden compare", exc)
    except BaseException:
        outputs.discard()
        raise
    if not getattr(args, "quiet", False):
        summary = sys.stderr if to_stdout else sys.stdout
        print(result.summary(), file=summary)
        for line in result.failures():
            print(f"FAIL {line}", file=sys.stderr)
        if result.report_dir is not None:
            print(f"report: {result.report_dir / 'index.html'}", file=summary)
    else:   # -q still names why the input is unusable (exit 2), one line per scene
        for s in result.scenes:
            if s.status == "error":
                print(f"golden compare: error: {s.name}: {' '.join(s.error.split())}",
                      file=sys.stderr)
    return result.exit_code


@_guarded("golden candidate")
def _cmd_candidate(args):
    from .candidate import candidate
    twice = next((n for i, n in enumerate(args.scene or ()) if n in args.scene[:i]), None)
    if twice is not None:   # before anything is read or rendered
        return _error(args, "golden candidate", ValueError(f"--scene {twice} is given twice"),
                      usage=True)
    result = candidate(args.golden_dir, args.out, backend=args.backend, scenes=args.scene,
                       threads=args.threads, wait=not args.no_wait,
                       on_wait=lambda holder: _say(args, f"waiting for {holder} to finish "
                                                         f"writing {args.out}"),
                       on_scene=lambda name, what: _say(args, f"{name}: {what}"))
    if not getattr(args, "quiet", False):
        print(f"{args.backend} backend ({result['renderer']}): rendered "
              f"{len(result['rendered'])} scene(s) into {args.out}, skipped "
              f"{len(result['skipped'])}")
        for name, reason in result["skipped"].items():
            print(f"skipped {name}: {reason}")
        if result["rendered"]:
            scenes = " ".join(f"--scene {n}" for n in result["rendered"])
            print(f"compare with: refraster golden compare {args.golden_dir} {args.out} {scenes}")
    return EXIT_PASS


def register(subparsers):
    """Add the ``golden`` command (``generate`` and ``compare``) to an argparse subparsers
    object; each sets ``func`` to a handler ``func(args) -> exit status``."""
    golden = subparsers.add_parser(
        "golden", help="generate golden images or compare a backend against them",
        description="Golden images: reference buffers a GPU backend is compared against.")
    _common(golden)
    sub = golden.add_subparsers(dest="golden_command", metavar="{generate,compare,candidate}")
    golden.set_defaults(func=lambda args: _error(
        args, "golden", ValueError("a subcommand is required: generate or compare"),
        usage=True))

    g = sub.add_parser("generate", help="render the golden scenes into DIR")
    _common(g)
    g.add_argument("--out", metavar="DIR", help="golden directory to write")
    g.add_argument("--scene", metavar="NAME", action="append",
                   help="a registered scene (repeatable; default: all)")
    g.add_argument("--scene-file", metavar="TOML", action="append",
                   help="a TOML scene description (repeatable)")
    g.add_argument("--update", action="store_true",
                   help="replace an existing golden directory (other scenes are kept)")
    g.add_argument("--list", action="store_true", help="list the registered scenes and exit")
    g.add_argument("--sweep", metavar="KEY=V1,V2", action="append",
                   help="pass every value of KEY to the scene functions (repeatable: every "
                        "combination); scenes are named <scene>__<key>_<value>")
    g.add_argument("--size", metavar="WxH", action="append",
                   help="render at this resolution too (repeatable); scenes are named "
                        "<scene>__<W>x<H>")
    g.add_argument("--jobs", metavar="N", type=_positive_int,
                   help="render in N worker processes of one thread each, the scenes grouped "
                        "by technique (default: min(CPUs, 2); 1 = in this process)")
    g.add_argument("--workers", metavar="N", type=_positive_int,
                   help="render on a Dask LocalCluster of N processes (N > 1; 1 = serial)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="render on an existing Dask cluster (e.g. tcp://host:8786)")
    g.add_argument("--convention", choices=("gl", "vulkan", "d3d12", "metal", "webgpu"),
                   help="emit the scenes in that API's conventions (raster fields, the "
                        "projection converted to its clip depth, the winding flip; "
                        "docs/backends.md); plain-rendering scenes only (default: those)")
    g.add_argument("--no-wait", action="store_true",
                   help="if another run is writing DIR, exit 2 naming it instead of waiting")
    g.add_argument("--candidate-subpixel-bits", metavar="N", type=_candidate_bits, default=8,
                   help="the sub-pixel bits of the candidates the golden is for, 4 to 8 "
                        "(default 8, as the CTS reference renderer and current desktop GPUs; 4 "
                        "for devices at OpenGL's minimum): the allowances assume it "
                        "(docs/tolerance.md)")
    g.set_defaults(func=_cmd_generate)

    c = sub.add_parser("compare", help="compare CANDIDATE_DIR against GOLDEN_DIR")
    _common(c)
    c.add_argument("golden_dir", metavar="GOLDEN_DIR")
    c.add_argument("candidate_dir", metavar="CANDIDATE_DIR")
    c.add_argument("--report", metavar="DIR", help="write an HTML report into DIR")
    c.add_argument("--mode", choices=MODES, default=None,
                   help="tolerant: coverage masks and value intervals stored in the golden; "
                        "exact: bit-exact (default: tolerant when the golden stores "
                        "allowances, else exact)")
    c.add_argument("--profile", choices=PROFILES, default=None,
                   help="compare with this metric profile from the manifest instead")
    c.add_argument("--tolerance", metavar="[SCENE:][BUFFER.]KEY=VALUE", action="append",
                   help="override a tolerance (repeatable), e.g. color.max_flip_mean=0.02")
    c.add_argument("--scene", metavar="NAME", action="append",
                   help="compare only this scene (repeatable)")
    c.add_argument("--json", metavar="FILE",
                   help="write the metrics as JSON ('-': to standard output, the summary "
                        "then goes to stderr)")
    c.add_argument("--no-wait", action="store_true",
                   help="if another run is writing the report directory, exit 2 naming it")
    c.set_defaults(func=_cmd_compare)

    k = sub.add_parser("candidate", help="render GOLDEN_DIR's scene packages with another "
                                         "backend into a candidate directory")
    _common(k)
    k.add_argument("golden_dir", metavar="GOLDEN_DIR")
    k.add_argument("--backend", choices=("gl", "wgpu"), default="gl",
                   help="gl: the GLSL backend refraster.gl (OpenGL 3.3 core on headless EGL; "
                        "the extra 'gl'); wgpu: the WGSL backend refraster.wgpu (WebGPU "
                        "through wgpu-py, default limits; the extra 'wgpu')")
    k.add_argument("--out", metavar="CANDIDATE_DIR", required=True,
                   help="candidate directory to write (nothing, empty, or a candidate "
                        "refraster wrote; replaced atomically)")
    k.add_argument("--scene", metavar="NAME", action="append",
                   help="render only this scene (repeatable; default: every scene the "
                        "backend supports)")
    k.add_argument("--threads", metavar="N", type=_positive_int,
                   help="rasterizer threads of Mesa's llvmpipe or lavapipe (LP_NUM_THREADS)")
    k.add_argument("--no-wait", action="store_true",
                   help="if another run is writing CANDIDATE_DIR, exit 2 naming it")
    k.set_defaults(func=_cmd_candidate)
    return golden


class _Parser(argparse.ArgumentParser):
    # a usage error is one line (with or without --debug), exit status 2
    def error(self, message):
        print(f"{self.prog}: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        raise SystemExit(EXIT_UNUSABLE)


def main(argv=None):
    """Standalone entry point: ``main(["golden", "compare", GOLDEN, CANDIDATE])`` or, without
    the leading ``golden``, ``main(["compare", GOLDEN, CANDIDATE])``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    first = next((i for i, a in enumerate(argv) if a not in ("-q", "--quiet", "--debug")),
                 len(argv))
    if argv[first:first + 1] != ["golden"]:
        argv.insert(first, "golden")
    from .io.write import Terminated, terminate_as_interrupt
    parser = _Parser(prog="refraster")
    parser.add_argument("-q", "--quiet", action="store_true")
    parser.add_argument("--debug", action="store_true")
    register(parser.add_subparsers(dest="command", parser_class=_Parser))
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    try:
        with terminate_as_interrupt():
            return args.func(args)
    except KeyboardInterrupt as exc:
        print("refraster: interrupted", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130


if __name__ == "__main__":
    sys.exit(main())
