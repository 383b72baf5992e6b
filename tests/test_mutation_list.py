"""The mutation list stays runnable: every mutant of ``tests/mutation/mutants.py`` names
snippets that occur exactly once in today's sources and test files that exist. CI runs only
the ``--fast`` subset; without this check a refactor can leave a mutant of the full list (the
long tier, docs/testing.md) pointing at code that moved, found only when the long tier refuses
to start."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

RUN = Path(__file__).parent / "mutation" / "run.py"


def _runner():
    spec = importlib.util.spec_from_file_location("mutation_run", RUN)
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("mutation_run", mod)
    spec.loader.exec_module(mod)
    return mod


def test_every_mutant_of_the_full_list_applies_once():
    run = _runner()
    bad = [b for m in run.MUTANTS for b in run.check(m)]
    assert not bad, "\n".join(bad)
    assert len(run.MUTANTS) >= 40
