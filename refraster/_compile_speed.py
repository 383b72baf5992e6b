"""Faster Numba compiles of refraster's kernels, with the same machine code.

A profile of a cold compile of the fused tile kernel (``cProfile`` around
``warmup.warm_only([SPLIT_KERNEL])``, Numba 0.68.1, 2026-12-02) put 62 % of it in Numba's copy
propagation, ``numba.core.ir_utils.copy_propagate``, and nearly all of that in one line of it:
its fixed-point loop keeps a copy of the map ``{block label: set of (lhs, rhs) variable-name
pairs}`` to compare the next round with, and makes it with ``copy.deepcopy``, which walks every
pair of every set through Python's generic deep copy (5.6 million tuple copies for that one
kernel; IR-inlined helpers make functions of hundreds of blocks and thousands of copies, and
the parfor passes run the analysis again on each loop body). The pairs are tuples of strings,
immutable, so the deep copy of that map is a dictionary of copies of its sets holding the very
same tuples: ``{label: set(pairs) …}`` builds exactly that. Its caller,
``init_copy_propagate_data``, also rebuilds a block's set of assigned names once per copy of
the whole program inside a double loop; computing it once per block gives the same set.

:func:`install` (called by :mod:`refraster._config`, which every kernel module imports) swaps
the two functions' code for these equivalents **only while one of refraster's kernels
compiles** (a ``numba:compile`` event listener; Numba compiles under its global compiler lock,
so nothing else compiles in the process meanwhile), and only when the installed Numba's source
of both functions is the one read here (SHA-256 of their source text): a Numba whose functions
differ keeps its own code. The results of the two functions are equal (``tests/
test_compile_speed.py`` compares them on the IR of refraster's kernels, and the machine code
of the render kernels compiled with and without the swap), so every compiled kernel and every
output byte is the same; only the compile is faster (``docs/performance.md``, "Copy
propagation"). ``REFRASTER_COMPILE_SPEEDUP=0`` turns it off.
"""

from __future__ import annotations

import hashlib
import inspect
import os
import threading

__all__ = ["install", "check", "state", "AUDITED"]

#: SHA-256 of ``inspect.getsource`` of the Numba functions whose code is swapped, as read in
#: Numba 0.59–0.68.1 (the text has not changed in those releases).
AUDITED = {
    "copy_propagate": "b607f90ff29db1cef4a6ca4f00481dd308f300e829154053daea3d3066305b62",
    "init_copy_propagate_data":
        "5cf4a6ab79e0dee0034580443f4e12d5e962e26f31388616bb73193c845918b1",
}


# The two replacements are written to run with ``numba.core.ir_utils``'s globals (their code
# object replaces the original's, and a function's globals belong to the function, not to its
# code): ``compute_cfg_from_blocks``, ``init_copy_propagate_data``, ``get_block_copies`` and
# ``config`` are that module's.

def _copy_propagate(blocks, typemap):  # pragma: no cover - runs as Numba's own function
    cfg = compute_cfg_from_blocks(blocks)  # noqa: F821 (ir_utils' global)
    entry = cfg.entry_point()
    c_data = init_copy_propagate_data(blocks, entry, typemap)  # noqa: F821
    (gen_copies, all_copies, kill_copies, in_copies, out_copies) = c_data
    old_point = None
    # The original deep-copies out_copies; its sets hold tuples of strings, so a copy of
    # each set (the same tuples) is that deep copy.
    new_point = {label: set(copies) for label, copies in out_copies.items()}
    while old_point != new_point:
        for label in blocks.keys():
            if label == entry:
                continue
            predecs = [i for i, _d in cfg.predecessors(label)]
            in_copies[label] = out_copies[predecs[0]].copy()
            for p in predecs:
                in_copies[label] &= out_copies[p]
            out_copies[label] = (gen_copies[label]
                                 | (in_copies[label] - kill_copies[label]))
        old_point = new_point
        new_point = {label: set(copies) for label, copies in out_copies.items()}
    if config.DEBUG_ARRAY_OPT >= 1:  # noqa: F821
        print("copy propagate out_copies:", out_copies)
    return in_copies, out_copies


def _init_copy_propagate_data(blocks, entry, typemap):  # pragma: no cover - as above
    gen_copies, extra_kill = get_block_copies(blocks, typemap)  # noqa: F821
    all_copies = set()
    for label in gen_copies:
        all_copies |= gen_copies[label]
    kill_copies = {}
    for label, gen_set in gen_copies.items():
        kill_copies[label] = killed = set()
        extra = extra_kill[label]
        # The names this block assigns: the original computes this set again for every
        # copy of the program, inside the loop below.
        assigned = {lhs for lhs, rhs in gen_set}
        for lhs, rhs in all_copies:
            if lhs in extra or rhs in extra:
                killed.add((lhs, rhs))
            if ((lhs, rhs) not in gen_set
                    and (lhs in assigned or rhs in assigned)):
                killed.add((lhs, rhs))
    in_copies = {label: all_copies.copy() for label in blocks.keys()}
    in_copies[entry] = set()
    out_copies = {}
    for label in blocks.keys():
        out_copies[label] = (gen_copies[label]
                             | (in_copies[label] - kill_copies[label]))
    out_copies[entry] = gen_copies[entry]
    return (gen_copies, all_copies, kill_copies, in_copies, out_copies)


_REPLACEMENTS = {"copy_propagate": _copy_propagate,
                 "init_copy_propagate_data": _init_copy_propagate_data}

_lock = threading.Lock()
_state = {"installed": False, "reason": "not installed", "depth": 0, "swaps": 0}
_originals = {}


def _source_digest(func):
    try:
        return hashlib.sha256(inspect.getsource(func).encode()).hexdigest()
    except (OSError, TypeError):
        return None


def _swap(to_fast):
    from numba.core import ir_utils
    for name, original in _originals.items():
        getattr(ir_utils, name).__code__ = (
            _REPLACEMENTS[name].__code__ if to_fast else original)


def _is_ours(dispatcher):
    py_func = getattr(dispatcher, "py_func", None)
    return py_func is not None and getattr(py_func, "__module__", "").startswith("refraster.")


def _listener_class():
    from numba.core import event

    class _Scope(event.Listener):
        """Swaps the code in while a refraster kernel compiles (nested compiles included)."""

        def on_start(self, ev):
            if _is_ours(ev.data.get("dispatcher")):
                with _lock:
                    _state["depth"] += 1
                    if _state["depth"] == 1:
                        _swap(True)
                        _state["swaps"] += 1

        def on_end(self, ev):
            if _is_ours(ev.data.get("dispatcher")):
                with _lock:
                    _state["depth"] -= 1
                    if _state["depth"] == 0:
                        _swap(False)

    return _Scope


def check(audited=None):
    """Why the swap cannot be installed (a sentence), or ``None`` when the installed Numba's
    two functions are the source read here (``audited``: expected digests; tests pass others)."""
    from numba.core import ir_utils
    audited = AUDITED if audited is None else audited
    for name in _REPLACEMENTS:
        func = getattr(ir_utils, name, None)
        if func is None or _source_digest(func) != audited.get(name):
            return f"numba.core.ir_utils.{name} is not the source refraster audited"
    return None


def install():
    """Install the scoped swap once per process (unless ``REFRASTER_COMPILE_SPEEDUP=0`` or
    :func:`check` finds another Numba); :func:`state` says whether it is on, and why not."""
    with _lock:
        if _state["installed"]:
            return state()
        if os.environ.get("REFRASTER_COMPILE_SPEEDUP", "1").strip() == "0":
            _state["reason"] = "off (REFRASTER_COMPILE_SPEEDUP=0)"
            return state()
        why = check()
        if why is not None:
            _state["reason"] = f"off ({why})"
            return state()
        from numba.core import event, ir_utils
        _originals.update((name, getattr(ir_utils, name).__code__) for name in _REPLACEMENTS)
        event.register("numba:compile", _listener_class()())
        _state["installed"] = True
        _state["reason"] = "on"
    return state()


def state():
    """``(on, reason)``: whether the copy-propagation speed-up is installed."""
    return _state["installed"], _state["reason"]
