"""Render golden scenes in a worker process (``refraster golden generate --jobs N`` starts these).

``python -m refraster.golden.worker TASKS_JSON NAME ...``

``TASKS_JSON`` maps each task name to ``[registered scene, parameters, candidate bits]`` (the
sweeps' and sizes' keyword arguments, the candidate's declared sub-pixel bits); a name of
:data:`refraster._workers.WARM_TASKS` compiles kernels ahead instead. Each task is rendered by :func:`refraster.golden.generate.render_task` — the unit of
work of the serial run, so the bytes are the same — in its own temporary directory; nothing is
written anywhere else. Its answer is one JSON line on stdout, ``{"scene", "item", "files",
"error"}``: the manifest entry and every file's bytes (base64) by its path relative to the
golden directory. The parent checks them and writes them into the golden it builds
(:func:`refraster.golden.generate.generate`). Compiles are announced on stderr for the
parent's progress line (:func:`refraster._workers.serve`).
"""

from __future__ import annotations

import base64
import json
import sys

__all__ = ["main"]


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    from .._workers import serve
    from .generate import render_task
    from .scenes import available_scenes
    spec, names = json.loads(argv[0]), argv[1:]
    registry = available_scenes()

    def run(name):
        scene, params, bits = spec[name]
        _, item, files = render_task(name, registry[scene], dict(params), bits)
        return {"item": item,
                "files": {rel: base64.b64encode(data).decode("ascii")
                          for rel, data in files.items()}}

    serve(names, run, key="scene", empty={})
    return 0


if __name__ == "__main__":
    sys.exit(main())
