"""Canonical solids: watertight, outward, pinned face counts, deterministic, validated."""

import hashlib
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from refraster import scenes
from refraster.scenes import solids

# (faces, Euler characteristic) at full detail and in the quick variant. The Euler
# characteristic pins the topology: 2 − 2·genus per closed component.
PINNED = {
    "cube": ((12, 2), (12, 2)),
    "icosphere": ((1280, 2), (320, 2)),
    "torus": ((2304, 0), (768, 0)),
    "fluted_column": ((13760, 2), (4320, 2)),
    "nested_shells": ((5120, 8), (1280, 8)),  # four spheres
    # genus 6: 10 openings between 5 spaces (outside + 4 rooms) → 10 − 5 + 1 independent loops
    "building": ((260, -10), (260, -10)),
    # genus 9: six bolt holes and three oil holes
    "crank": ((99404, -16), (5596, -16)),
}


def test_every_solid_is_pinned():
    assert set(PINNED) == set(scenes.SOLIDS) == set(scenes.QUICK)


@pytest.fixture(scope="module")
def meshes():
    return {(name, quick): scenes.solid(name, quick=quick)
            for name in scenes.SOLIDS for quick in (False, True)}


@pytest.mark.parametrize("quick", [False, True], ids=["full", "quick"])
@pytest.mark.parametrize("name", list(PINNED))
def test_watertight_outward_and_pinned(meshes, name, quick):
    mesh = meshes[name, quick]
    faces, euler = PINNED[name][quick]
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    assert len(mesh.faces) == faces
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.is_volume  # watertight, consistent and positive volume: CCW seen from outside
    assert mesh.euler_number == euler
    # no degenerate triangles (a zero-area face has no normal, no coverage and no facing)
    assert mesh.area_faces.min() > 0.0


def test_crank_is_about_100k_faces_and_scales_with_segments():
    # the docstring promises ~172 faces per segment
    for seg in (16, 64, 256):
        n = len(solids.crank(seg).faces)
        assert 140 * seg <= n <= 200 * seg, (seg, n)
    assert 95_000 <= PINNED["crank"][0][0] <= 105_000


def test_cube_and_shell_volumes_hand_worked(meshes):
    assert meshes["cube", False].volume == pytest.approx(1.0, abs=1e-12)
    # volumes scale with r³, so the shells hold V1·(1 − .8³ + .6³ − .4³) exactly
    unit = solids.icosphere(3).volume
    expected = unit * (1.0 - 0.8 ** 3 + 0.6 ** 3 - 0.4 ** 3)
    assert meshes["nested_shells", False].volume == pytest.approx(expected, rel=1e-12)


def test_building_volume_hand_worked(meshes):
    outer = 10.0 * 6.25 * 7.0
    rooms = 2.75 * 6.5 * (5.625 + 3.625 + 3.625 + 5.625)
    # openings × wall or slab thickness 0.25
    doors = 4 * (1.0 * 2.05 * 0.25)
    windows = 0.25 * 1.2 * (1.8 + 1.6 + 1.5 + 1.5 + 2.0)
    stairwell = 2.0 * 1.5 * 0.25
    expected = outer - rooms - doors - windows - stairwell
    assert meshes["building", False].volume == pytest.approx(expected, rel=1e-12)
    assert meshes["building", False].bounds.tolist() == [[0, 0, 0], [10, 6.25, 7]]


def test_torus_volume_converges_to_pappus():
    # Pappus: 2πR · πr², approached as both segment counts grow
    mesh = solids.torus(1.0, 0.35, 256, 128)
    assert mesh.volume == pytest.approx(2 * math.pi ** 2 * 0.35 ** 2, rel=1e-3)


def test_nested_shells_inner_spheres_are_reversed(meshes):
    mesh = meshes["nested_shells", False]
    per = 20 * 4 ** 3
    signs = []
    for k in range(4):
        part = mesh.submesh([np.arange(k * per, (k + 1) * per)], append=True)
        signs.append(np.sign(part.volume))
    assert signs == [1, -1, 1, -1]


def test_fluted_column_has_flutes():
    # the shaft's cross-section at mid height: radius dips at every flute's centre
    mesh = solids.fluted_column(flutes=20)
    y = mesh.vertices[:, 1]
    ring_y = y[np.argmin(np.abs(y - 0.5 * y.max()))]
    mid = mesh.vertices[y == ring_y]
    assert len(mid) == 20 * 8
    r = np.hypot(mid[:, 0], mid[:, 2])
    assert r.max() - r.min() > 0.02
    theta = np.arctan2(-mid[:, 2], mid[:, 0]) % (2 * np.pi)
    deepest = theta[r < r.min() + 1e-3]
    # flute centres are at (k + 0.5)/20 of the turn
    phase = (deepest * 20 / (2 * np.pi)) % 1.0
    assert np.all(np.abs(phase - 0.5) < 0.13)


@settings(deadline=None, max_examples=10)
@given(flutes=st.integers(3, 24), k=st.integers(4, 10), rings=st.integers(2, 30))
def test_fluted_column_face_count_formula(flutes, k, rings):
    mesh = solids.fluted_column(flutes=flutes, samples_per_flute=k, rings=rings)
    assert len(mesh.faces) == 2 * flutes * k * (rings + 19)
    assert mesh.is_volume


@settings(deadline=None, max_examples=10)
@given(m=st.integers(3, 40), n=st.integers(3, 40),
       minor=st.floats(0.05, 0.95, allow_nan=False))
def test_torus_property(m, n, minor):
    mesh = solids.torus(1.0, minor, m, n)
    assert len(mesh.faces) == 2 * m * n
    assert mesh.is_volume and mesh.euler_number == 0


@pytest.mark.parametrize("s", range(5))
def test_icosphere_counts(s):
    mesh = solids.icosphere(s, radius=2.0)
    assert len(mesh.faces) == 20 * 4 ** s and len(mesh.vertices) == 10 * 4 ** s + 2
    assert np.allclose(np.linalg.norm(mesh.vertices, axis=1), 2.0)


def _digest(mesh):
    return hashlib.sha256(mesh.vertices.tobytes() + mesh.faces.tobytes()).hexdigest()


_DIGEST_SCRIPT = """
import hashlib
from refraster import scenes
for name in sorted(scenes.SOLIDS):
    m = scenes.solid(name, quick=True)
    print(name, hashlib.sha256(m.vertices.tobytes() + m.faces.tobytes()).hexdigest())
"""


def test_deterministic_in_process_and_across_processes(meshes):
    here = {}
    for name in sorted(scenes.SOLIDS):
        again = scenes.solid(name, quick=True)
        assert np.array_equal(again.vertices, meshes[name, True].vertices)
        assert np.array_equal(again.faces, meshes[name, True].faces)
        here[name] = _digest(again)
    out = subprocess.run([sys.executable, "-c", _DIGEST_SCRIPT], capture_output=True, text=True,
                         check=True).stdout
    there = dict(line.split() for line in out.splitlines())
    assert there == here


@pytest.mark.parametrize("call, exc", [
    (lambda: solids.icosphere(-1), ValueError),
    (lambda: solids.icosphere(8), ValueError),
    (lambda: solids.icosphere(2.0), TypeError),
    (lambda: solids.icosphere(True), TypeError),
    (lambda: solids.cube(0.0), ValueError),
    (lambda: solids.cube(float("nan")), ValueError),
    (lambda: solids.cube("1"), TypeError),
    (lambda: solids.torus(1.0, 1.0), ValueError),
    (lambda: solids.torus(1.0, 0.3, 2, 8), ValueError),
    (lambda: solids.nested_shells((1.0, 0.5, 0.2)), ValueError),
    (lambda: solids.nested_shells((0.5, 1.0)), ValueError),
    (lambda: solids.nested_shells(()), ValueError),
    (lambda: solids.nested_shells((1.0, -0.5)), ValueError),
    (lambda: solids.fluted_column(flutes=2), ValueError),
    (lambda: solids.fluted_column(height=-1.0), ValueError),
    (lambda: solids.crank(4), ValueError),
    (lambda: solids.crank(32.0), TypeError),
    (lambda: scenes.solid("teapot"), ValueError),
    (lambda: scenes.solid(3), TypeError),
])
def test_bad_input(call, exc):
    with pytest.raises(exc):
        call()


def test_error_names_the_argument():
    with pytest.raises(ValueError, match="minor_radius"):
        solids.torus(1.0, 2.0)
    with pytest.raises(ValueError, match="segments"):
        solids.crank(2)
