"""refraster/_compile_speed.py: Numba's copy propagation made faster while refraster's kernels
compile, with the same results and the same machine code.

Both directions: the replacements give the original functions' results, set for set and in
the same iteration order, on the IR of every kernel of refraster; the same comparison catches
the two slips a cheaper copy or a hoist invites (an aliased "copy" that ends the fixed point
after one round; a kill test that forgets the right-hand name); the render kernels compiled
with and without the swap are the same machine code; the swap is active only while a
refraster kernel compiles; another Numba's source keeps Numba's own code.
"""

import copy
import inspect
import os
import subprocess
import sys
import types as pytypes

import pytest

numba = pytest.importorskip("numba")
from numba import njit  # noqa: E402
from numba.core import compiler, event, ir_utils, types  # noqa: E402

from refraster import _compile_speed as cs  # noqa: E402
from refraster import warmup  # noqa: E402


class _Types(dict):
    """A typemap for untyped IR: every name typed, some as arrays (mutable: their in-place
    operations kill copies), so that both kill paths of the analysis are exercised."""

    def __missing__(self, name):
        return types.float64[:] if len(name) % 3 == 0 else types.float64


def _with_ir_utils_globals(func):
    return pytypes.FunctionType(func.__code__, vars(ir_utils), func.__name__)


def _variant(func, *edits):
    """``func``'s source with ``edits`` (old, new) applied, compiled with ir_utils' globals."""
    src = inspect.getsource(func)
    for old, new in edits:
        assert old in src, old
        src = src.replace(old, new)
    namespace = dict(vars(ir_utils))
    exec(src, namespace)
    return namespace[func.__name__]


def _ordered(result):
    return [{k: list(v) for k, v in part.items()} if isinstance(part, dict) else list(part)
            for part in result]


def _kernel_irs():
    irs = []
    for disp in warmup.kernels(warmup.KERNEL_MODULES):
        irs.append((warmup._name(disp), compiler.run_frontend(disp.py_func).blocks))
    return irs


@pytest.fixture(scope="module")
def kernel_irs():
    return _kernel_irs()


def _differs(func_a, func_b, irs, init=False):
    """The kernels whose IR gives different results (or iteration orders) under the two."""
    out = []
    for name, blocks in irs:
        if init:
            a = func_a(copy.deepcopy(blocks), min(blocks), _Types())
            b = func_b(copy.deepcopy(blocks), min(blocks), _Types())
        else:
            a = func_a(copy.deepcopy(blocks), _Types())
            b = func_b(copy.deepcopy(blocks), _Types())
        if _ordered(a) != _ordered(b):
            out.append(name)
    return out


def test_the_installed_numba_is_the_audited_source():
    # Numba 0.68.1 (the CI's) has the audited source; another Numba keeps its own code and
    # this says so locally rather than failing a user's suite.
    why = cs.check()
    if why is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(why)
    assert cs.state() == (True, "on") or os.environ.get("REFRASTER_COMPILE_SPEEDUP") == "0"


def test_guard_refuses_other_source():
    assert cs.check() is None or cs.check().endswith("not the source refraster audited")
    bad = dict(cs.AUDITED, copy_propagate="0" * 64)
    assert "copy_propagate" in cs.check(bad)
    bad = dict(cs.AUDITED, init_copy_propagate_data="0" * 64)
    assert "init_copy_propagate_data" in cs.check(bad)


def test_copy_propagate_equals_numba_on_every_kernel(kernel_irs):
    assert len(kernel_irs) > 50
    original = ir_utils.copy_propagate      # outside a compile: Numba's own code
    assert original.__code__ is not cs._copy_propagate.__code__
    assert _differs(original, _with_ir_utils_globals(cs._copy_propagate), kernel_irs) == []


def test_init_copy_propagate_data_equals_numba_on_every_kernel(kernel_irs):
    original = ir_utils.init_copy_propagate_data
    fast = _with_ir_utils_globals(cs._init_copy_propagate_data)
    assert _differs(original, fast, kernel_irs, init=True) == []


def test_the_comparison_catches_an_aliased_copy(kernel_irs):
    # The slip a cheaper copy invites: keeping a reference instead of a copy ends the fixed
    # point after one round. The fused tile kernel's IR needs more than one.
    aliased = _variant(cs._copy_propagate,
                       ("new_point = {label: set(copies) for label, copies in "
                        "out_copies.items()}\n    while", "new_point = out_copies\n    while"),
                       ("        new_point = {label: set(copies) for label, copies in "
                        "out_copies.items()}", "        new_point = out_copies"))
    caught = _differs(ir_utils.copy_propagate, aliased, kernel_irs)
    assert "refraster.raster.rasterizer._fused_pass" in caught


def test_the_comparison_catches_a_half_kill_test(kernel_irs):
    half = _variant(cs._init_copy_propagate_data,
                    ("if lhs in extra or rhs in extra:", "if lhs in extra:"))
    assert _differs(ir_utils.init_copy_propagate_data, half, kernel_irs, init=True)


def test_swap_is_scoped_to_refraster_compiles():
    if not cs.state()[0]:
        pytest.skip(cs.state()[1])
    seen = []

    class Probe(event.Listener):
        def on_start(self, ev):
            seen.append(ir_utils.copy_propagate.__code__ is cs._copy_propagate.__code__)

        def on_end(self, ev):
            pass

    def ours(x):
        return x + 1.0

    def theirs(x):
        return x + 2.0

    ours.__module__ = "refraster._probe"
    with event.install_listener("numba:compile", Probe()):
        njit(cache=False)(theirs)(1.0)
        njit(cache=False)(ours)(1.0)
    assert seen == [False, True]
    assert ir_utils.copy_propagate.__code__ is not cs._copy_propagate.__code__
    assert ir_utils.init_copy_propagate_data.__code__ is not (
        cs._init_copy_propagate_data.__code__)


_DUMP = """
import re, sys
from refraster import warmup, _compile_speed
warmup.warm_only(["refraster.raster.primitive._classify",
                  "refraster.raster.rasterizer._bin_pass"])
out = []
for name in ("refraster.raster.primitive._classify", "refraster.raster.rasterizer._bin_pass"):
    [disp] = [d for d in warmup.kernels(warmup.CORE_MODULES) if warmup._name(d) == name]
    [sig] = disp.signatures
    out.append(re.sub("0x[0-9a-f]+", "", disp.inspect_asm(sig)))
print(_compile_speed.state()[0], _compile_speed._state["swaps"])
sys.stdout.write("".join(out))
"""


def _compiled(tmp_path, speedup, **extra):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / f"cache{speedup}{len(extra)}"),
               REFRASTER_COMPILE_SPEEDUP=speedup, **extra)
    run = subprocess.run([sys.executable, "-c", _DUMP], env=env, capture_output=True,
                         text=True, timeout=600, check=True)
    head, _, asm = run.stdout.partition("\n")
    return head, asm


def test_same_machine_code_with_and_without(tmp_path):
    # Two parallel kernels of the render path, compiled cold in two processes: the swap on
    # (it swapped for them) and off; the machine code differs only in the addresses Numba
    # puts in generated names.
    if cs.check() is not None:
        pytest.skip(cs.check())
    head_on, asm_on = _compiled(tmp_path, "1")
    head_off, asm_off = _compiled(tmp_path, "0")
    assert head_on.split()[0] == "True" and int(head_on.split()[1]) >= 2
    assert head_off.split() == ["False", "0"]
    assert "_bin_pass" in asm_on and len(asm_on) > 10_000
    assert asm_on == asm_off
    # The comparison sees a change of code generation: LLVM's optimisation off (NUMBA_OPT=0),
    # the swap on, gives other machine code for the same kernels.
    _, asm_opt0 = _compiled(tmp_path, "1", NUMBA_OPT="0")
    assert "_bin_pass" in asm_opt0 and asm_opt0 != asm_on
