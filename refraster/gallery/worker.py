"""Render gallery sections in a worker process (``refraster gallery`` starts these).

``python -m refraster.gallery.worker OUT_DIR [--quick] SECTION ...``

A name of :data:`WARM_TASKS` compiles kernels ahead instead of rendering. Each section's
result is one JSON line on stdout: ``{"section", "items", "error"}`` with the
items as ``[section, filename, caption]``. Each kernel the worker compiles (a cache miss) is
one line ``refraster-compiled module.qualname`` on stderr (and
``refraster-compiling …`` when it starts), so that the parent counts them in
its progress line. The parent sets ``NUMBA_NUM_THREADS=1``: the sections run side by side, one
thread each, and a kernel's output bytes do not depend on its thread count. The protocol and
the process handling are :mod:`refraster._workers`' (shared with ``golden generate --jobs``).
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

from .._workers import COMPILED, STARTING, WARM_TASKS, serve

__all__ = ["main", "COMPILED", "STARTING", "WARM_TASKS"]   # the names moved, kept here too


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    quick = "--quick" in argv
    argv = [a for a in argv if a != "--quick"]
    out_dir, names = Path(argv[0]), argv[1:]

    from . import split_item

    def run(name):
        section, part = split_item(name)   # "name#k": part k of the section
        module = importlib.import_module(f"refraster.gallery.{section}")
        kw = {} if part is None else {"part": part}
        return {"items": [[i.section, i.filename, i.caption]
                          for i in module.render(out_dir, quick=quick, **kw)]}

    serve(names, run, key="section", empty={"items": []})
    return 0


if __name__ == "__main__":
    sys.exit(main())
