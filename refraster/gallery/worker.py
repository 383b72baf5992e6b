"""Render gallery sections in a worker process (``refraster gallery`` starts these).

``python -m refraster.gallery.worker OUT_DIR [--quick] SECTION ...``

A name of :data:`WARM_TASKS` compiles kernels ahead instead of rendering. Each section's
result is one JSON line on stdout: ``{"section", "items", "error"}`` with the
items as ``[section, filename, caption]``. Each kernel the worker compiles (a cache miss) is
one line ``refraster-compiled module.qualname`` on stderr (and
``refraster-compiling …`` when it starts), so that the parent counts them in
its progress line. The parent sets ``NUMBA_NUM_THREADS=1``: the sections run side by side, one
thread each, and a kernel's output bytes do not depend on its thread count.
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

COMPILED = "refraster-compiled "
STARTING = "refraster-compiling "
#: Names a worker takes besides sections: compile kernels ahead (no pictures), by the
#: function of :mod:`refraster.warmup` that does it. ``refraster gallery`` gives one to a
#: worker on a first run, so that a section later loads those kernels from the cache.
WARM_TASKS = {"warm-clipsurface": "warm_clipsurface_side"}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    quick = "--quick" in argv
    argv = [a for a in argv if a != "--quick"]
    out_dir, names = Path(argv[0]), argv[1:]

    from ..warmup import compile_listener
    from . import split_item

    def compiled(disp):
        print(f"{COMPILED}{disp.py_func.__module__}.{disp.py_func.__qualname__}",
              file=sys.stderr, flush=True)

    def starting(disp):
        print(f"{STARTING}{disp.py_func.__module__}.{disp.py_func.__qualname__}",
              file=sys.stderr, flush=True)

    with compile_listener(compiled, starting):
        for name in names:
            items, error = [], None
            try:
                if name in WARM_TASKS:
                    getattr(importlib.import_module("refraster.warmup"), WARM_TASKS[name])()
                else:
                    section, part = split_item(name)   # "name#k": part k of the section
                    module = importlib.import_module(f"refraster.gallery.{section}")
                    kw = {} if part is None else {"part": part}
                    items = [[i.section, i.filename, i.caption]
                             for i in module.render(out_dir, quick=quick, **kw)]
            except Exception as exc:
                error = f"{type(exc).__name__}: {' '.join(str(exc).split()) or type(exc).__name__}"
            print(json.dumps({"section": name, "items": items, "error": error}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
