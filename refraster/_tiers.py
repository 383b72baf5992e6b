"""Two tiers of the render kernels: a quickly compiled one for a first run, the full one after.

A first :func:`refraster.render` in a fresh Numba cache compiles the seven kernels of its path
(:data:`RENDER_KERNELS`); compiled as shipped — ``parallel=True``, small helpers inlined at
Numba IR level — that is about 40 CPU seconds (docs/performance.md, "The first run"). The
**quick tier** is the same Python source compiled with cheaper flags: serial (``prange`` runs
as ``range``) and every helper a called function (no IR inlining, no Python wrapper), about a
third of the compile. It does the same arithmetic in the same order, no ``fastmath`` in either,
so every output byte is the same (``tests/test_tiers.py`` compares digests of both tiers);
only its frames are slower.

``REFRASTER_TIER`` chooses: ``auto`` (default) runs the **full tier** when its kernels are in
the cache, and otherwise the quick tier while a second process
(``python -m refraster.warmup --full-tier``, lower priority, outliving this one if need be)
compiles the full tier into the cache; that process first compiles three of the quick tier's kernels
(:data:`SPLIT_KERNELS`) while this one compiles the others, the fused tile kernel among them. Once the
full tier is in the cache the next frame loads and runs it (the swap). ``full`` always runs
the full tier (compiling it here when it is not cached: the commands that compile ahead,
``refraster warmup``, ``gallery``, ``golden generate``, set it); ``quick`` always the quick one.

:func:`state` says which tier ran last and why (``refraster info``, ``refraster render -v``).
The quick twins are new functions from the kernels' code with their own qualified names
(``NAME__quick``), so their cache files are their own.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import threading
import time
import types

from numba.core.registry import CPUDispatcher

from ._config import QHJIT, QJIT

__all__ = ["RENDER_KERNELS", "SPLIT_KERNELS", "FULL", "QUICK", "kernel", "current", "force",
           "state", "preview", "twin", "cached", "compiled_here", "split_wanted"]

#: The kernels ``refraster.render`` compiles for a frame and its colour when no face crosses
#: a clipping plane, by ``module.qualname``: the ones with a quick tier.
RENDER_KERNELS = (
    "refraster.raster.primitive._transform32", "refraster.raster.primitive._vertex_pass",
    "refraster.raster.primitive._classify", "refraster.raster.rasterizer._bin_pass",
    "refraster.raster.rasterizer._fused_pass", "refraster.raster.gbuffer.finalize",
    "refraster.raster.gbuffer.shade")
#: The quick-tier kernels the second process compiles first, in groups, saying each group's
#: names when done: binning (this process needs it ~2 s in), then ``finalize`` and ``shade``
#: (needed after the fused tile kernel, the largest, which this process compiles meanwhile).
SPLIT_KERNELS = (("refraster.raster.rasterizer._bin_pass",),
                 ("refraster.raster.gbuffer.finalize", "refraster.raster.gbuffer.shade"))

_FUSED = "refraster.raster.rasterizer._fused_pass"

FULL, QUICK = "full", "quick"
_SUFFIX = "__quick"
#: How often a quick-tier process looks whether the full tier has reached the cache.
_POLL_SECONDS = 0.5

_lock = threading.RLock()
_twins = {}
_st = {"tier": None, "why": "no frame yet", "ran": None, "proc": None, "next_poll": 0.0,
       "split": {}, "said": set(), "full": frozenset()}


def _is_kernel(obj):
    return isinstance(obj, CPUDispatcher) and obj.py_func.__module__.startswith("refraster.")


def _dispatcher(name):
    module, attr = name.rsplit(".", 1)
    return getattr(importlib.import_module(module), attr)


def twin(disp, helper=False):
    """The quick-tier twin of the kernel ``disp`` (memoized): its code with refraster's jitted
    functions among its globals replaced by their twins (helpers), compiled with the quick
    flags under the qualified name ``NAME__quick``."""
    from numba import njit
    key = (id(disp), helper)
    with _lock:
        got = _twins.get(key)
        if got is not None:
            return got
        py = disp.py_func
        glb = dict(py.__globals__)
        fn = types.FunctionType(py.__code__, glb, py.__name__, py.__defaults__, py.__closure__)
        fn.__qualname__ = py.__qualname__ + _SUFFIX + ("_helper" if helper else "")
        fn.__module__ = py.__module__
        fn.__doc__ = py.__doc__
        got = njit(**(QHJIT if helper else QJIT))(fn)
        _twins[key] = got
        # the globals it calls, read when it compiles: their twins (a name it calls itself
        # by, too)
        for name in _global_names(py.__code__):
            v = py.__globals__.get(name)
            if _is_kernel(v):
                glb[name] = got if v is disp else twin(v, helper=True)
        return got


def _global_names(code):
    names = set(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            names |= _global_names(c)
    return names


def cached(disp):
    """Whether ``disp`` has a compiled specialisation in the on-disk cache valid for its
    current source."""
    try:
        return bool(disp._cache._cache_file._load_index())
    except Exception:   # an unreadable index is a cold one: Numba will compile
        return False


def split_wanted():
    """Whether the second process compiles :data:`SPLIT_KERNELS` first: only beside this
    process's largest compile, the quick fused tile kernel (when the full one is cached,
    this process has little to compile)."""
    return not cached(_dispatcher(_FUSED))


def _full_cached():
    return all(cached(_dispatcher(n)) for n in RENDER_KERNELS)


def _cached_full_kernels():
    return frozenset(id(d) for d in map(_dispatcher, RENDER_KERNELS) if cached(d))


def _setting():
    value = os.environ.get("REFRASTER_TIER", "auto").strip().lower() or "auto"
    if value not in ("auto", FULL, QUICK):
        raise ValueError(f"REFRASTER_TIER: {value!r} is not one of auto, full, quick")
    return value


def force(tier):
    """Run ``tier`` (:data:`FULL`, :data:`QUICK`) from now on in this process, or ``None``:
    decide again by ``REFRASTER_TIER`` at the next frame."""
    if tier not in (FULL, QUICK, None):
        raise ValueError(f"tier: {tier!r} is not one of 'full', 'quick', None")
    with _lock:
        _st["tier"], _st["full"], _st["ran"] = tier, frozenset(), None
        _st["why"] = "set by the program" if tier else "no frame yet"


def _start_second_process():
    """Start ``python -m refraster.warmup --full-tier``: the quick fused kernel, then the
    full tier, into the cache (it keeps one at a time per cache with a lock file)."""
    env = dict(os.environ, REFRASTER_TIER=FULL)
    try:
        return subprocess.Popen([sys.executable, "-m", "refraster.warmup", "--full-tier"],
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, env=env, text=True,
                                start_new_session=True)
    except OSError:
        return None


def _decide():
    setting = _setting()
    if setting != "auto":
        _st["tier"], _st["why"] = setting, f"REFRASTER_TIER={setting}"
        return setting
    if _full_cached():
        _st["tier"], _st["why"] = FULL, "its kernels are in the cache"
        return FULL
    _st["tier"] = QUICK
    _st["why"] = "the full tier is not in the cache: a second process compiles it"
    # a kernel whose full tier is in the cache runs it: the same bytes either way
    _st["full"] = _cached_full_kernels()
    if os.environ.get("REFRASTER_TIER_SECOND", "1") != "0":
        _st["proc"] = _start_second_process()
        if _st["proc"] is not None and split_wanted():
            _st["split"] = {id(d): n for n, d in ((n, _dispatcher(n)) for g in SPLIT_KERNELS
                                                  for n in g)
                            if id(d) not in _st["full"] and not cached(twin(d))}
    _st["next_poll"] = time.monotonic() + _POLL_SECONDS
    return QUICK


def _poll():
    now = time.monotonic()
    if now < _st["next_poll"]:
        return QUICK
    _st["next_poll"] = now + _POLL_SECONDS
    proc = _st["proc"]
    if proc is not None and proc.poll() is None:
        return QUICK   # still compiling: the cache is not complete before it ends
    if _setting() == "auto" and _full_cached():
        _st["tier"], _st["why"] = FULL, "swapped in: the second process put it in the cache"
        _st["ran"] = None
        if proc is not None:
            proc.stdout.close()
            _st["proc"] = None
        return FULL
    return QUICK


def current():
    """The tier this process runs now (deciding it at the first call, swapping to the full
    tier once it is in the cache)."""
    tier = _st["tier"]
    if tier == FULL:
        return tier
    with _lock:
        tier = _st["tier"]
        if tier is None:
            return _decide()
        if tier == QUICK and _st["why"].startswith("the full tier is not"):
            return _poll()
        return tier


def _wait_for_split(name):
    """The second process compiles the quick twins of :data:`SPLIT_KERNELS` first and names
    each group on its standard output when it is in the cache: wait for ``name`` (then the
    twin loads from the cache), or for the end of its output (then it compiles here)."""
    proc = _st["proc"]
    while name not in _st["said"]:
        try:
            line = proc.stdout.readline() if proc is not None else ""
        except (OSError, ValueError):
            line = ""
        if not line or line.split() in (["done"], ["busy"]):   # not coming: compile here
            _st["said"].update(_st["split"].values())
            break
        _st["said"].update(line.split())


def kernel(disp):
    """The kernel to call for ``disp`` in this process's tier: ``disp`` itself (full) or its
    quick twin. Anything not a refraster kernel (a stand-in of ``refraster.warmup``) is
    returned as is. In the full tier a dictionary look-up and a comparison (warm frames pay
    nothing more)."""
    if _st["tier"] == FULL:
        return disp
    return _quick_or_full(disp)


def _quick_or_full(disp):
    if not _is_kernel(disp):
        return disp
    tier = current()
    if tier == FULL:
        return disp
    if id(disp) in _st["full"]:
        _st["ran"] = _st["ran"] or FULL
        return disp
    _st["ran"] = QUICK
    name = _st["split"].get(id(disp))
    if name is not None and name not in _st["said"]:
        with _lock:
            _wait_for_split(name)
    return twin(disp)


def compiled_here():
    """The quick twins (``module.qualname__quick``) this process compiles in the quick tier:
    those not in the cache whose full kernel is not either, less the second process's."""
    out = []
    for name in RENDER_KERNELS:
        d = _dispatcher(name)
        if id(d) in _st["full"] or id(d) in _st["split"] or cached(twin(d)):
            continue
        out.append(name + _SUFFIX)
    return out


def preview():
    """``(tier, why)``: the tier a ``render`` in this process runs now or would run first,
    without deciding it or starting anything (``refraster info``)."""
    with _lock:
        if _st["tier"] is not None:
            return _st["tier"], _st["why"]
    setting = _setting()
    if setting != "auto":
        return setting, f"REFRASTER_TIER={setting}"
    n = sum(map(cached, map(_dispatcher, RENDER_KERNELS)))
    if n == len(RENDER_KERNELS):
        return FULL, "its kernels are in the cache"
    return QUICK, (f"{n} of {len(RENDER_KERNELS)} of its kernels in the cache: a first render "
                   "runs the quick tier while a second process compiles the full one")


def state():
    """``(ran, why)``: the tier this process's render kernels run (``None`` before the first
    frame decided it; in a process that has run the quick tier, ``quick`` until the full tier
    is swapped in) and why."""
    ran = FULL if _st["tier"] == FULL else _st["ran"]
    return ran, _st["why"]
