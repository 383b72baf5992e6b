"""Worker processes of one thread each, shared by ``refraster gallery`` and ``refraster golden
generate`` (``--jobs N``).

The parent starts ``python -m MODULE ARGS…`` for a group of tasks (one process per group, at
most ``jobs`` at a time, in the order given: the longest first) with ``NUMBA_NUM_THREADS=1``;
a kernel's output bytes do not depend on its thread count. In the worker, :func:`serve` runs the
group's tasks one after the other and prints one JSON line per task on stdout (``{KEY: name,
…result, "error": one line or null}``); each kernel it compiles (a cache miss) is one line
``refraster-compiled module.qualname`` on stderr (``refraster-compiling …`` when it starts), so
that the parent counts it in its progress line (:class:`refraster.warmup.CompileProgress`);
a log record of warning level and up is one line ``refraster-logged LOGGER<TAB>message``,
which the parent logs again (the command shows it as one line, as in process).

On a first run (the pipeline's kernels not in the cache) the parent compiles the pipeline's
kernels itself (:func:`refraster.warmup.warm_core`) while the groups that do not need them run
in a worker — with :data:`WARM_TASKS` appended, the clip surfaces' kernels that need no
pipeline kernel (and, for the goldens, their fused tile pass) — and only then starts the other
groups, which load the pipeline's kernels from the cache instead of each compiling them (a
group that needs a warm task's kernels waits for that worker: ``after_warm``).

Nothing here writes a file: the workers' results come back to the parent, which decides what to
write. It stands on the tools floor with :mod:`refraster.warmup` (docs/architecture.md,
"Floors"): the gallery, the goldens and the command use it; the core and the techniques never
import it.
"""

from __future__ import annotations

import importlib
import json
import os
import queue as _queue
import subprocess
import sys
import threading
import time

__all__ = ["COMPILED", "STARTING", "LOGGED", "WARM_TASKS", "serve", "run_groups",
           "cold_start_groups"]

COMPILED = "refraster-compiled "
STARTING = "refraster-compiling "
#: A log record of a worker (warning level and up), ``LOGGER<TAB>message`` after this: the
#: parent logs it again, so that it reaches the command's one-line warnings
#: (:mod:`refraster._logs`) as it would in process.
LOGGED = "refraster-logged "
#: Names a worker takes besides its own tasks: compile kernels ahead (no result), by the
#: function of :mod:`refraster.warmup` that does it. On a first run the parent gives one to a
#: worker, so that a later task loads those kernels from the cache.
WARM_TASKS = {"warm-clipsurface": "warm_clipsurface_side", "warm-fused-clip": "warm_fused_clip"}


def _one_line(exc):
    return f"{type(exc).__name__}: {' '.join(str(exc).split()) or type(exc).__name__}"


def serve(names, run, *, key, empty=None, stream=None):
    """In a worker: run each of ``names`` — a :data:`WARM_TASKS` name, or ``run(name)`` → a
    dict of JSON values — and print one line ``{key: name, **result, "error": …}`` per name on
    ``stream`` (default stdout), in order. A task that raises answers ``{key: name, **empty,
    "error": "Type: message"}`` (one line, no traceback) and the next one runs. Compiles are
    announced on stderr for the parent's progress line. Anything else the tasks print on
    stdout goes to stderr, so that stdout holds the answers only."""
    from .warmup import compile_listener

    out = sys.stdout if stream is None else stream
    empty = {} if empty is None else dict(empty)

    def compiled(disp):
        print(f"{COMPILED}{disp.py_func.__module__}.{disp.py_func.__qualname__}",
              file=sys.stderr, flush=True)

    def starting(disp):
        print(f"{STARTING}{disp.py_func.__module__}.{disp.py_func.__qualname__}",
              file=sys.stderr, flush=True)

    import logging

    class Relay(logging.Handler):
        def emit(self, record):
            try:
                text = " ".join(record.getMessage().split())
                if record.exc_info and record.exc_info[1] is not None:
                    text += f" ({_one_line(record.exc_info[1])})"
                print(f"{LOGGED}{record.name}\t{text}", file=sys.stderr, flush=True)
            except Exception:   # a broken record must not break the task
                self.handleError(record)

    relay = Relay(logging.WARNING)
    logging.getLogger().addHandler(relay)
    saved, sys.stdout = sys.stdout, sys.stderr
    try:
        with compile_listener(compiled, starting):
            for name in names:
                try:
                    result = dict(empty)
                    if name in WARM_TASKS:
                        getattr(importlib.import_module("refraster.warmup"), WARM_TASKS[name])()
                    else:
                        result = dict(run(name))
                    line = json.dumps({key: name, **result, "error": None})
                except Exception as exc:   # the task's error, one line; the next task runs
                    line = json.dumps({key: name, **empty, "error": _one_line(exc)})
                out.write(line + "\n")
                out.flush()
    finally:
        sys.stdout = saved
        logging.getLogger().removeHandler(relay)


def cold_start_groups(queue, jobs, independent, clip_side_cold, *, clip_group=None,
                      fused_clip=False):
    """The groups to start on a first run while the parent compiles the pipeline's kernels,
    taken off ``queue`` (a list of groups, each a list of task names): the groups whose tasks
    all need no pipeline kernel (``independent(name)``; at most ``jobs - 1`` groups) and —
    with two or more jobs, ``clip_side_cold`` and a queued group for which ``clip_group(group)``
    is true — ``warm-clipsurface`` after them, the clip surfaces' kernels that need no pipeline
    kernel (:func:`refraster.warmup.warm_clipsurface_side`): their tasks compile longest (the
    critical path of a first run), so the core that would idle while the pipeline compiles
    compiles those ahead. With ``fused_clip`` (and the same conditions, the fused pass not in
    the cache) ``warm-fused-clip`` follows: the clip surfaces' fused tile pass
    (:func:`refraster.warmup.warm_fused_clip`), the largest single compile of the run; pass
    ``clip_group`` to :func:`run_groups` as ``after_warm`` too, so that the clip surfaces'
    group waits for it instead of compiling the pass a second time beside it."""
    first = [g for g in queue if all(independent(n) for n in g)][:max(jobs - 1, 1)]
    for group in first:
        queue.remove(group)
    first = [list(g) for g in first]
    warm = []
    if jobs >= 2 and clip_group is not None and any(clip_group(g) for g in queue):
        if clip_side_cold:
            warm.append("warm-clipsurface")
        if fused_clip:
            from .warmup import FUSED_CLIP_KERNEL, KERNEL_MODULES, cache_state
            cached, n = cache_state(KERNEL_MODULES, only=(FUSED_CLIP_KERNEL,))
            if cached < n:
                warm.append("warm-fused-clip")
    if warm:
        if first:
            first[0].extend(warm)
        else:
            first = [warm]
    return first


def run_groups(module, groups, jobs, *, key, command=None, progress=None, cold_start=None,
               fail_fast=False, after_warm=None):
    """Run ``groups`` (lists of task names) in worker processes ``python -m module …`` of one
    thread each, at most ``jobs`` at a time, in order; yield ``(name, result, error)`` for every
    task name (not for :data:`WARM_TASKS`) as the answers arrive, in this thread.

    ``command(group)`` → the arguments after ``-m module`` (default: the group's names).
    ``progress``: a :class:`refraster.warmup.CompileProgress` counting the workers' compiles.
    ``cold_start(queue, clip_side_cold)`` → the groups to start first when the pipeline's
    kernels are not in the cache (taken off ``queue``; :func:`cold_start_groups`): then this
    process compiles the pipeline's kernels before the other groups start. A task whose worker
    ended without answering yields the error ``"worker process failed …"`` (its last line on
    stderr, or its exit status). With ``fail_fast`` the first error stops the run: the yield is
    the last one and every worker still running is killed. Closing the generator (or an
    exception in the consumer) kills every worker still running. A queued group for which
    ``after_warm(group)`` is true does not start while a worker given a :data:`WARM_TASKS`
    name runs (it would compile those kernels a second time beside it); the next group in
    the queue that may start does."""
    import logging

    from .warmup import (CLIPSURFACE_SIDE_KERNELS, KERNEL_MODULES, STREAM_KERNELS, cache_state,
                         warm_core)
    command = (lambda group: list(group)) if command is None else command
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    if env.get("REFRASTER_TIER", "auto").strip().lower() in ("", "auto"):
        env["REFRASTER_TIER"] = "full"   # many frames: the full tier (refraster/_tiers.py)
    answers = _queue.Queue()
    running = []

    def read(proc, group):
        tail, bad = [], []

        def stderr():
            for line in proc.stderr:
                if line.startswith(COMPILED):
                    if progress is not None:
                        progress.add(line[len(COMPILED):].strip())
                elif line.startswith(STARTING):
                    if progress is not None:
                        progress.starting()
                elif line.startswith(LOGGED):
                    name, _, text = line[len(LOGGED):].rstrip("\n").partition("\t")
                    logging.getLogger(name or "refraster.worker").warning("%s", text)
                elif line.strip():
                    tail[:] = (tail + [line.strip()])[-5:]

        def stdout():
            for line in proc.stdout:   # read to the end whatever comes: the worker never blocks
                try:
                    r = json.loads(line)
                    name, error = r.pop(key), r.pop("error")
                    if not isinstance(name, str) or name not in group or not (
                            error is None or isinstance(error, str)):
                        raise ValueError(f"an answer for {name!r}, not one of {group}")
                except (ValueError, KeyError, TypeError, AttributeError) as exc:
                    bad[:] = [f"unreadable answer ({_one_line(exc)})"]
                    continue
                answers.put((name, r, error))
        threads = [threading.Thread(target=f, daemon=True) for f in (stderr, stdout)]
        for t in threads:
            t.start()
        return threads, tail, bad

    def start(group):
        cmd = [sys.executable, "-m", module, *command(group)]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                stdin=subprocess.DEVNULL, env=env, text=True)
        running.append((proc, group, *read(proc, group)))

    answered = set()

    def drain():
        out = []
        while True:
            try:
                name, result, error = answers.get_nowait()
            except _queue.Empty:
                return out
            if name in WARM_TASKS or name in answered:
                continue   # a failed warm-up only leaves its kernels to the task that needs them
            answered.add(name)
            out.append((name, result, error))

    def reap():
        """The answers that arrived, and for each worker that ended, its unanswered tasks
        (failed)."""
        ended = []
        for entry in list(running):
            if entry[0].poll() is not None:
                _close(entry)
                running.remove(entry)
                ended.append(entry)
        out = drain()
        for proc, group, _, tail, bad in ended:
            why = "; ".join(bad + tail[-1:]) or "no message"
            for name in group:
                if name not in WARM_TASKS and name not in answered:
                    answered.add(name)
                    out.append((name, None, f"worker process failed (exit status "
                                            f"{proc.returncode}): {why}"))
        return out

    queue = [list(g) for g in groups]
    try:
        cached, total = cache_state(KERNEL_MODULES, only=STREAM_KERNELS)
        if cached < total and cold_start is not None:
            side, n_side = cache_state(KERNEL_MODULES, only=CLIPSURFACE_SIDE_KERNELS)
            for group in cold_start(queue, side < n_side):
                start(group)
            # here: counted by the progress line
            warm_core(clip=True, stream=True, multisample=True)
        while queue or running:
            for name, result, error in reap():
                yield name, result, error
                if error is not None and fail_fast:
                    return
            while queue and len(running) < jobs:
                warming = after_warm is not None and any(
                    n in WARM_TASKS for entry in running for n in entry[1])
                ready = [i for i, g in enumerate(queue) if not (warming and after_warm(g))]
                if not ready:
                    break
                start(queue.pop(ready[0]))
            time.sleep(0.05)
    finally:
        for entry in running:
            if entry[0].poll() is None:
                entry[0].kill()
            entry[0].wait()
            _close(entry)


def _close(entry):
    """A worker that ended: its readers finish (end of its output) and its pipes close."""
    proc, _, threads = entry[:3]
    for t in threads:
        t.join()
    proc.stdout.close()
    proc.stderr.close()
