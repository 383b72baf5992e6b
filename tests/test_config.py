"""Every Numba kernel takes its flags from refraster._config (no fastmath, cache=True)."""

import pathlib
import re

import refraster._config as cfg

ROOT = pathlib.Path(__file__).resolve().parents[1] / "refraster"


def test_flags():
    for flags in (cfg.JIT, cfg.PJIT, cfg.IJIT, cfg.QJIT, cfg.QHJIT):
        assert flags["cache"] is True
        assert flags["fastmath"] is False


def test_no_kernel_hard_codes_flags():
    bad = []
    for path in ROOT.rglob("*.py"):
        text = path.read_text()
        for m in re.finditer(r"@(?:numba\.)?(?:njit|jit|vectorize|guvectorize|stencil)\b(\([^)]*\))?", text):
            args = (m.group(1) or "").strip("()").strip()
            if args not in ("**JIT", "**PJIT", "**IJIT"):
                bad.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
        if re.search(r"fastmath\s*=\s*True", text):
            bad.append(f"{path.relative_to(ROOT)}: fastmath=True")
    assert not bad, "kernels must use @njit(**JIT), @njit(**PJIT) or @njit(**IJIT):\n" + "\n".join(bad)
