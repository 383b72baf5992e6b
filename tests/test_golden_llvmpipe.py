"""A second backend (Mesa llvmpipe, tests/golden_llvmpipe_backend.py) renders the plain-rendering
golden scenes from their exported packages alone and passes the conformant compare."""

import ast

import pytest
from conftest import LLVMPIPE_BACKEND as BACKEND
from conftest import llvmpipe_frames

from refraster import golden


def test_backend_imports_no_refraster():
    tree = ast.parse(BACKEND.read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert names and not [n for n in names if n.split(".")[0] == "refraster"]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    root = tmp_path_factory.mktemp("llvmpipe")
    # OpenGL's conventions: this backend draws nothing else (the scenes in other APIs'
    # conventions are tests/test_golden_conventions.py's; the catalogue's, one in a [0, 1] clip
    # depth, are drawn by refraster.gl on llvmpipe in tests/test_conformance_catalogue.py)
    scenes = [n for n, e in golden.available_scenes().items() if e.technique == "render"
              and e.build.__module__ not in ("refraster.golden.convention_scenes",
                                             "refraster.golden.catalogue_scenes")]
    golden.generate(root / "golden", scenes)
    return root, scenes


def test_llvmpipe_renders_packages_and_passes_conformant_compare(rendered, oracle):
    oracle("moderngl")
    root, scenes = rendered
    # -I: no current directory or PYTHONPATH on the path; the backend reads the packages only
    info = llvmpipe_frames(root / "golden", root / "llvmpipe", timeout=300)
    assert info["renderer"].startswith("llvmpipe")
    assert sorted(info["scenes"]) == sorted(scenes)
    assert info["refraster_modules"] == []

    result = golden.compare(root / "golden", root / "llvmpipe", profile="conformant",
                            report=root / "report")
    assert result.exit_code == 0, result.summary()
    # the exact profile sees llvmpipe's sub-pixel differences: the two profiles differ
    exact = golden.compare(root / "golden", root / "llvmpipe", profile="exact")
    assert exact.exit_code == 1
    print(result.summary())
    # the conformant profile is not blind: one interior id off fails it
    import numpy as np
    cand = root / "llvmpipe" / "render_cube" / "buffers.npz"
    with np.load(cand) as z:
        b = {k: z[k] for k in z.files}
    r, c = np.argwhere(b["prim_id"] >= 0)[len(np.argwhere(b["prim_id"] >= 0)) // 2]
    b["prim_id"][r, c] = 999
    np.savez(root / "edited.npz", **b)
    (root / "edited" / "render_cube").mkdir(parents=True)
    (root / "edited.npz").replace(root / "edited" / "render_cube" / "buffers.npz")
    edited = golden.compare(root / "golden", root / "edited", profile="conformant",
                            scenes=["render_cube"], tolerances=["prim_id.max_fraction=0"])
    # id 999 is also no id of the 12-face cube: the domain check names it too
    assert {line.split(":")[0] for line in edited.failures()} == {"render_cube/prim_id"}
    assert any("domain:id_range" in line for line in edited.failures())
