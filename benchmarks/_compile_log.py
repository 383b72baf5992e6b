"""Run the ``refraster`` command with Numba's compile events recorded, and dump them as JSON.

``python -m benchmarks._compile_log OUT.json -- gallery --out DIR -q``

Each ``numba:compile`` event (a cache miss that compiles one specialisation) is timed from its
start to its end. A kernel compiled while another is being compiled (a callee that is not
inlined) nests inside the caller's event, so each record has its inclusive time and its
exclusive time (the inclusive time minus that of the compiles nested directly inside it); the
exclusive times add up to the time spent compiling. Used by :mod:`benchmarks.cold_start`.
"""

from __future__ import annotations

import json
import sys
import time


def main(argv):
    out, rest = argv[0], argv[argv.index("--") + 1:]
    from numba.core import event

    records, stack = [], []

    class Timer(event.Listener):
        def on_start(self, ev):
            stack.append([time.perf_counter(), 0.0])

        def on_end(self, ev):
            t0, nested = stack.pop()
            dt = time.perf_counter() - t0
            if stack:
                stack[-1][1] += dt
            disp = ev.data["dispatcher"]
            py = disp.py_func
            records.append(dict(
                kernel=py.__qualname__, module=py.__module__,
                args=[str(a) for a in ev.data["args"]],
                inclusive=dt, exclusive=dt - nested, depth=len(stack)))

    event.register("numba:compile", Timer())
    from refraster.cli import main as cli_main
    t0 = time.perf_counter()
    status = cli_main(rest)
    wall = time.perf_counter() - t0
    with open(out, "w") as fh:
        json.dump(dict(status=status, wall=wall, records=records), fh)
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
