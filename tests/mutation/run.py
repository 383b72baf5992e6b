"""Mutation run of the test suite over a curated list of realistic bugs (issue 30).

Each mutant of :mod:`tests.mutation.mutants` is one single-point bug, the kind a careless
refactor or a GPU port makes (``<=`` → ``<``, ``rint`` → ``floor``, a transposed kernel, a
halved constant, a tie broken the other way), applied to a kernel **and** to its NumPy or
brute-force twin when one exists, as happens when a formula is misread rather than mistyped.
The runner takes a snapshot of the repository when it starts, copies it to a temporary directory
for each mutant (the worktree is never modified, and edits made during a run do not leak into
it), applies one mutant there, runs ``python -m pytest -x -q <tests>`` in the copy with a timeout,
and records:

- **killed**: pytest reported a failing test (the first failing test id is kept);
- **survived**: every selected test passed;
- **error**: the mutant did not import or compile (a syntax, import or Numba typing error), the
  tests could not be collected, or the run timed out. An error is not a kill: a mutant that
  breaks compilation says nothing about whether the tests read the formula.

Why a curated runner rather than a general tool such as mutmut:

- the bugs that matter here are misreadings of the paper's formulas, which must be planted in
  the kernel and in its twin at once (the twin would otherwise catch them, as it would not if
  the same team misread the formula twice); mutmut mutates one line of one file at a time;
- most of the code is Numba kernels: mutmut's blind operator and constant swaps would mostly
  make them fail to type-check (an error, not a kill) or be equivalent (``+ 0`` → ``- 0``),
  and the ones it keeps would be drowned among thousands of uninteresting mutants;
- each copy has its own ``NUMBA_CACHE_DIR``; compiling the kernels afresh costs minutes per
  mutant on a busy machine, so a list of a few dozen chosen mutants (each with the test files of
  its module) is what fits in a run, and a one-per-module subset (``--fast``) fits in CI.

The Numba cache: the run first passes the unmutated tests (a mutant "killed" by a test that
fails anyway would mean nothing) in a copy at a fixed path per worker, which fills a warm cache.
Each mutant is copied to that same path with the same time stamps and gets a copy of the warm
cache from which the entries of the mutated files **and of every file importing them** (directly
or not; a cached kernel may have inlined a mutated one, and Numba only checks the time stamp of
the caller's own file) are deleted. ``--cold`` compiles everything afresh instead.

Usage::

    python tests/mutation/run.py                 # the whole list, prints a Markdown table
    python tests/mutation/run.py --fast          # one mutant per module (the CI subset)
    python tests/mutation/run.py --only ldi_parity_strict --only cutaway_slope_tan
    python tests/mutation/run.py --list          # the mutants, without running them

Exit status: 0 when every mutant run was killed, 1 when one survived or errored, 2 on bad
arguments or a mutant whose ``old`` snippet does not occur exactly once.
"""

from __future__ import annotations

import argparse
import ast
import concurrent.futures as cf
import dataclasses
import datetime as _dt
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from mutants import MUTANTS, Mutant  # noqa: E402

IGNORE = shutil.ignore_patterns(".git", "__pycache__", "*.pyc", ".pytest_cache", "*.egg-info",
                                ".hypothesis", "img", "out", "build", "dist")
# An error, not a kill: the mutant did not build (Numba typing/lowering, syntax, imports).
BUILD_ERRORS = re.compile(r"TypingError|LoweringError|NumbaError|UnsupportedError|SyntaxError|"
                          r"IndentationError|ImportError|ModuleNotFoundError|NameError")


def edits(m: Mutant):
    return [(m.file, m.old, m.new)] + list(m.twin)


def check(m: Mutant, root: Path = ROOT):
    """Refuse a mutant whose snippets do not each occur exactly once (or whose tests are
    missing); returns a list of complaints."""
    bad = []
    for file, old, new in edits(m):
        path = root / file
        if not path.is_file():
            bad.append(f"{m.name}: no file {file}")
            continue
        n = path.read_text().count(old)
        if n != 1:
            bad.append(f"{m.name}: the snippet {old!r} occurs {n} times in {file} (must be once)")
        if old == new:
            bad.append(f"{m.name}: the replacement of {old!r} in {file} is the same text")
    for t in list(m.tests) + list(m.ci):
        if not (root / t.split("::")[0]).is_file():
            bad.append(f"{m.name}: no test file {t.split('::')[0]}")
    return bad


def first_failure(out: str):
    for line in out.splitlines():
        if line.startswith(("FAILED ", "ERROR ")):
            return line.split(" ", 1)[1].split(" - ", 1)[0].strip()
    return None


def _module_files(root: Path):
    """Dotted module name → file, for the package and the tests."""
    out = {}
    for top in ("refraster", "tests"):
        for f in (root / top).rglob("*.py"):
            rel = f.relative_to(root).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f.relative_to(root).as_posix()
    return out


def import_graph(root: Path = ROOT):
    """file → set of files it imports (the package's and the tests' own modules only)."""
    mods = _module_files(root)
    graph = {}
    for name, file in mods.items():
        pkg = name if file.endswith("__init__.py") else name.rpartition(".")[0]
        deps = set()
        tree = ast.parse((root / file).read_text())
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg.split(".")[:len(pkg.split(".")) - (node.level - 1)]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            for t in targets:
                if t in mods:
                    deps.add(mods[t])
        graph[file] = deps
    return graph


def affected(files, graph):
    """The files that import (directly or through others) any of ``files``, and those files:
    their cached Numba kernels may have inlined a mutated one."""
    out = set(files)
    changed = True
    while changed:
        changed = False
        for f, deps in graph.items():
            if f not in out and deps & out:
                out.add(f)
                changed = True
    return out


def invalidate(cache: Path, files):
    """Delete the Numba cache entries of ``files`` (``<dir>_<hash>/<stem>.<function>…``)."""
    n = 0
    for f in files:
        p = Path(f)
        for d in cache.glob(f"{p.parent.name}_" + "?" * 40):
            for e in d.glob(f"{p.stem}.*"):
                e.unlink()
                n += 1
    return n


SOURCE = ROOT   # main() points this at a snapshot taken when the run starts


def _copy_repo(dst: Path):
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(SOURCE, dst, ignore=IGNORE)   # copy2: modification times kept


def _pytest(copy: Path, cache: Path, tests, timeout):
    env = dict(os.environ, PYTHONPATH=str(copy), NUMBA_CACHE_DIR=str(cache),
               PYTHONDONTWRITEBYTECODE="1")
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests]
    return subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True,
                          timeout=timeout)


class Slot:
    """One worker's fixed copy path and its warm Numba cache. Numba keys its cache by the
    source file's path and time stamp, so a copy made at the same path with the same time
    stamps reuses the compiled kernels; the mutated files and every file importing them
    (which may have inlined a mutated kernel) have their entries deleted first."""

    def __init__(self, base: Path, index: int, cold: bool):
        self.dir = base / f"slot{index}"
        self.repo = self.dir / "repo"
        self.warm = None if cold else self.dir / "warm-cache"

    def warm_up(self, tests, timeout):
        _copy_repo(self.repo)
        if self.warm is None:
            return None
        try:
            proc = _pytest(self.repo, self.warm, tests, timeout)
        except subprocess.TimeoutExpired:
            return f"the unmutated tests timed out after {timeout:.0f} s"
        if proc.returncode != 0:
            out = (proc.stdout + proc.stderr).strip().splitlines()
            return "the unmutated tests fail:\n    " + "\n    ".join(out[-15:])
        return None


def run_one(m: Mutant, timeout: float, slot: Slot, graph):
    t0 = time.monotonic()
    cache = slot.dir / f"cache-{m.name}"
    try:
        _copy_repo(slot.repo)
        copy = slot.repo
        for file, old, new in edits(m):
            path = copy / file
            text = path.read_text()
            assert text.count(old) == 1, (m.name, file)
            path.write_text(text.replace(old, new, 1))
        if slot.warm is not None:
            shutil.copytree(slot.warm, cache)
            invalidate(cache, affected({f for f, _, _ in edits(m)}, graph))
        try:
            proc = _pytest(copy, cache, m.tests, timeout)
        except subprocess.TimeoutExpired:
            return dict(status="error", detail=f"timeout after {timeout:.0f} s",
                        seconds=time.monotonic() - t0)
        out = proc.stdout + proc.stderr
        secs = time.monotonic() - t0
        if proc.returncode == 0:
            return dict(status="survived", detail="", seconds=secs)
        failed = first_failure(out)
        if proc.returncode == 1 and failed:
            # The first failure's own traceback: a build error there is not a kill.
            section = out.split("= FAILURES =", 1)[-1].split("short test summary", 1)[0]
            hit = BUILD_ERRORS.search(section)
            if hit:
                return dict(status="error", detail=f"{hit.group(0)} in {failed}", seconds=secs,
                            log=out)
            return dict(status="killed", detail=failed, seconds=secs)
        tail = " ".join(out.strip().splitlines()[-3:])[:200]
        return dict(status="error", detail=f"pytest exit {proc.returncode}: {tail}",
                    seconds=secs, log=out)
    finally:
        shutil.rmtree(cache, ignore_errors=True)


def where(m: Mutant):
    files = [m.file] + [f for f, _, _ in m.twin if f != m.file]
    return " + ".join(f"`{f}`" for f in dict.fromkeys(files))


def table(rows):
    lines = ["| mutant | module | where | bug | result | killed by |",
             "|---|---|---|---|---|---|"]
    for m, r in rows:
        by = r["detail"] if r["status"] == "killed" else (
            "survived" if r["status"] == "survived" else f"error: {r['detail']}")
        by = by.replace("|", "\\|")
        lines.append(f"| `{m.name}` | {m.module} | {where(m)} | {m.doc} | {r['status']} "
                     f"({r['seconds']:.0f} s) | {'`' + by + '`' if r['status'] == 'killed' else by} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", action="append", default=[], metavar="NAME",
                    help="run only this mutant (repeatable, or comma-separated)")
    ap.add_argument("--fast", action="store_true", help="one mutant per module (the CI subset)")
    ap.add_argument("--jobs", type=int, default=1, help="mutants run at once (default 1)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per mutant")
    ap.add_argument("--tests", nargs="+", metavar="TEST",
                    help="run these test files or node ids instead of each mutant's own (to "
                         "show that a new test kills a survivor)")
    ap.add_argument("--list", action="store_true", help="list the mutants and exit")
    ap.add_argument("--out", help="also write the Markdown table to this file")
    ap.add_argument("--cold", action="store_true",
                    help="compile every mutant's kernels from scratch (no warm Numba cache)")
    ap.add_argument("--workdir", help="directory for the copies (default: a new temporary one)")
    args = ap.parse_args(argv)
    if args.jobs < 1:
        print("error: --jobs must be at least 1", file=sys.stderr)
        return 2

    names = {m.name for m in MUTANTS}
    if len(names) != len(MUTANTS):
        print("error: two mutants share a name", file=sys.stderr)
        return 2
    only = [n for o in args.only for n in o.split(",") if n]
    unknown = [n for n in only if n not in names]
    if unknown:
        print(f"error: --only: no mutant named {', '.join(unknown)}", file=sys.stderr)
        return 2
    selected = [m for m in MUTANTS if (not only or m.name in only) and (not args.fast or m.fast)]
    if args.fast:   # the CI subset runs each mutant's killing tests only
        selected = [dataclasses.replace(m, tests=m.ci or m.tests) for m in selected]
    if not selected:
        print("error: no mutant selected", file=sys.stderr)
        return 2
    if args.tests:
        selected = [dataclasses.replace(m, tests=list(args.tests)) for m in selected]
    bad = [b for m in selected for b in check(m)]
    if bad:
        print("error: refusing to run:\n  " + "\n  ".join(bad), file=sys.stderr)
        return 2
    if args.list:
        for m in selected:
            print(f"{m.name:32s} {m.module:14s} {where(m)}  {m.doc}")
        return 0

    started = _dt.datetime.now(_dt.timezone.utc)
    base = Path(args.workdir or tempfile.mkdtemp(prefix="refraster-mutation-"))
    base.mkdir(parents=True, exist_ok=True)
    # one snapshot of the tree for the whole run: edits made meanwhile do not leak into it
    global SOURCE
    SOURCE = base / "source"
    if SOURCE.exists():
        shutil.rmtree(SOURCE)
    shutil.copytree(ROOT, SOURCE, ignore=IGNORE)
    graph = import_graph(SOURCE)
    slots = [Slot(base, i, args.cold) for i in range(args.jobs)]
    tests = list(dict.fromkeys(t for m in selected for t in m.tests))
    print(f"{len(selected)} mutants, {args.jobs} at a time, copies in {base}", file=sys.stderr)
    try:
        if not args.cold:
            print(f"warming the Numba cache: the unmutated {len(tests)} test files",
                  file=sys.stderr, flush=True)
        with cf.ThreadPoolExecutor(max_workers=args.jobs) as pool:
            for err in pool.map(lambda s: s.warm_up(tests, args.timeout * 4), slots):
                if err:
                    print(f"error: {err}", file=sys.stderr)
                    return 2
        warm_s = (_dt.datetime.now(_dt.timezone.utc) - started).total_seconds()
        free = list(slots)
        lock = threading.Lock()

        def work(m):
            with lock:
                slot = free.pop()
            try:
                return run_one(m, args.timeout, slot, graph)
            finally:
                with lock:
                    free.append(slot)

        results = {}
        with cf.ThreadPoolExecutor(max_workers=args.jobs) as pool:
            futs = {pool.submit(work, m): m for m in selected}
            for fut in cf.as_completed(futs):
                m = futs[fut]
                r = fut.result()
                results[m.name] = r
                print(f"  {m.name}: {r['status']} {r['detail']} ({r['seconds']:.0f} s)",
                      file=sys.stderr, flush=True)
                if r["status"] == "error" and r.get("log"):
                    print("    " + "\n    ".join(r["log"].strip().splitlines()[-15:]),
                          file=sys.stderr)
    finally:
        if not args.workdir:
            shutil.rmtree(base, ignore_errors=True)
    rows = [(m, results[m.name]) for m in selected]
    elapsed = (_dt.datetime.now(_dt.timezone.utc) - started).total_seconds()
    counts = {s: sum(r["status"] == s for _, r in rows) for s in ("killed", "survived", "error")}
    head = (f"Run {started:%Y-%m-%d %H:%M} UTC on {platform.node()} ({platform.machine()}, "
            f"{os.cpu_count()} cores, Python {platform.python_version()}), --jobs {args.jobs}: "
            f"{len(rows)} mutants, {counts['killed']} killed, {counts['survived']} survived, "
            f"{counts['error']} errors, {elapsed / 60:.1f} min "
            f"({'cold caches' if args.cold else f'{warm_s / 60:.1f} min of it warming the cache'}).")
    text = head + "\n\n" + table(rows) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    return 0 if counts["killed"] == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
