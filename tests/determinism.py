"""Run a script in fresh interpreters with NUMBA_NUM_THREADS (and REFRASTER_THREADS) = 1, 2, 2.

The determinism tests print digests (or the bytes themselves) from such a script and compare
the three outputs: identical bytes across runs and thread counts.
"""

import os
import subprocess
import sys

THREAD_COUNTS = ("1", "2", "2")


def outputs_by_thread_count(script, timeout=600):
    """stdout of ``python -c script`` under each of :data:`THREAD_COUNTS`, stripped."""
    outs = []
    for threads in THREAD_COUNTS:
        # REFRASTER_THREADS too: render would otherwise run small or busy frames on one thread
        env = dict(os.environ, NUMBA_NUM_THREADS=threads, REFRASTER_THREADS=threads)
        r = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                           text=True, timeout=timeout)
        assert r.returncode == 0, f"NUMBA_NUM_THREADS={threads}: {r.stderr}"
        outs.append(r.stdout.strip())
    return outs
