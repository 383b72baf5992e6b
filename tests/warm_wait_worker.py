"""A stand-in worker for ``tests/test_golden_jobs.py``'s test of
:func:`refraster._workers.run_groups` waiting for a warm task (``python -m warm_wait_worker
TASK…``): a :data:`refraster._workers.WARM_TASKS` name sleeps ``REFRASTER_TEST_WARM_SECONDS``,
any other task answers at once; each start and end of the process is a JSON line
``[event, group, time]`` appended to ``REFRASTER_TEST_WORKER_LOG``."""

import json
import os
import sys
import time

from refraster._workers import WARM_TASKS


def _log(event, group):
    with open(os.environ["REFRASTER_TEST_WORKER_LOG"], "a") as fh:
        fh.write(json.dumps([event, group, time.time()]) + "\n")


def main(names):
    _log("start", names)
    for name in names:
        if name in WARM_TASKS:
            time.sleep(float(os.environ.get("REFRASTER_TEST_WARM_SECONDS", "2")))
        print(json.dumps({"task": name, "error": None}), flush=True)
    _log("end", names)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
