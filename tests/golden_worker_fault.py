"""A golden worker process with a planted fault, for ``tests/test_golden_jobs.py`` only
(``generate.WORKER_MODULE`` is pointed here by the test; the real worker never reads this).

``REFRASTER_TEST_WORKER_FAULT`` = ``KIND:SCENE`` plants a fault at that scene, then runs the real
worker (:func:`refraster.golden.worker.main`):

* ``raise`` — the scene raises (the worker answers with the error and goes on),
* ``die`` — the worker process dies without answering (``os._exit``),
* ``escape`` — the answer holds a file outside the scene's directory,
* ``compiled`` — the worker announces a compiled kernel named SCENE on stderr, then works,
* ``warn`` — the scene logs a warning (logger ``trimesh``), then renders.

``REFRASTER_TEST_WORKER_LOG`` names a file each worker appends its group to (one JSON line).
"""

import importlib
import json
import os
import sys

from refraster._workers import COMPILED

generate = importlib.import_module("refraster.golden.generate")   # the module, not the function
worker = importlib.import_module("refraster.golden.worker")


def main():
    kind, _, target = os.environ.get("REFRASTER_TEST_WORKER_FAULT", "").partition(":")
    log = os.environ.get("REFRASTER_TEST_WORKER_LOG")
    if log:
        with open(log, "a") as fh:
            fh.write(json.dumps(sys.argv[2:]) + "\n")
    if kind == "compiled":
        print(f"{COMPILED}{target}", file=sys.stderr, flush=True)
    real = generate.render_task

    def planted(name, entry, params, bits):
        if name == target and kind == "raise":
            raise RuntimeError(f"planted fault in {name}")
        if name == target and kind == "warn":
            import logging
            logging.getLogger("trimesh").warning("planted warning in %s", name)
        if name == target and kind == "die":
            sys.stderr.write("dying on purpose\n")
            sys.stderr.flush()
            os._exit(7)
        name, item, files = real(name, entry, params, bits)
        if name == target and kind == "escape":
            files[f"{name}/../escaped.txt"] = b"outside"
        return name, item, files

    generate.render_task = planted
    return worker.main(sys.argv[1:])


if __name__ == "__main__":
    sys.exit(main())
