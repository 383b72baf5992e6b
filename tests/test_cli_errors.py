"""Every failure of the command line is one line naming the real cause, exit 2, whichever entry
point; third-party log records are one-line warnings, in full only with --debug (issue 18)."""

import subprocess
import sys

import numpy as np
import pytest
import trimesh

from refraster import RasterState, cli

PY = [sys.executable]


def _run(*args, timeout=300):
    return subprocess.run([*PY, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def textured_ply(path, texture="missing_texture.png"):
    """A box PLY with texture coordinates whose header names a texture that is not there (as
    trimesh's own fuze.ply does when copied without its picture)."""
    box = trimesh.creation.box()
    box.visual = trimesh.visual.TextureVisuals(
        uv=np.linspace(0.0, 1.0, 2 * len(box.vertices)).reshape(-1, 2))
    text = trimesh.exchange.ply.export_ply(box, encoding="ascii").decode()
    lines = text.splitlines(keepends=True)
    lines.insert(2, f"comment TextureFile {texture}\n")
    path.write_text("".join(lines))
    return path


@pytest.fixture
def mesh_file(tmp_path):
    path = tmp_path / "box.obj"
    trimesh.creation.box().export(path)
    return path


@pytest.mark.parametrize("argv, message", [
    (["--target", "inf", "0", "0"], "--target must be 3 finite numbers, got inf 0.0 0.0"),
    (["--eye", "1", "nan", "0"], "--eye must be 3 finite numbers, got 1.0 nan 0.0"),
    (["--fov", "0"], "--fov must be between 0 and 180 degrees (both excluded), got 0.0"),
    (["--fov", "inf"], "--fov must be between 0 and 180 degrees (both excluded), got inf"),
    (["--near", "-1"], "--near must be a finite number > 0, got -1.0"),
    (["--far", "inf"], "--far must be a finite number > 0, got inf"),
    (["--up", "0", "0", "0"], "--up must not be the zero vector"),
])
def test_camera_options_are_named(mesh_file, tmp_path, capsys, argv, message):
    assert cli.main(["render", str(mesh_file), "--out", str(tmp_path / "x.png"), *argv]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"refraster: error: {message}"]
    assert not (tmp_path / "x.png").exists()


def test_garbage_stl_names_the_file_not_a_missing_module(tmp_path, capsys, monkeypatch):
    stl = tmp_path / "garbage.stl"
    stl.write_bytes(np.random.default_rng(1).integers(0, 256, 1000, np.uint8).tobytes())
    monkeypatch.setitem(sys.modules, "charset_normalizer", None)   # as where it is missing
    assert cli.main(["render", str(stl), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"mesh file '{stl}' is not an STL file" in err[0], err
    assert "charset_normalizer" not in err[0]


def test_memory_error_is_one_line(mesh_file, tmp_path, capsys, monkeypatch):
    import refraster
    def boom(*args, **kwargs):
        raise MemoryError()
    monkeypatch.setattr(refraster, "render", boom)
    assert cli.main(["render", str(mesh_file), "--out", str(tmp_path / "x.png"), "-q"]) == 2
    assert capsys.readouterr().err.splitlines() == ["refraster: error: out of memory "
                                                    "(MemoryError)"]


def test_missing_texture_is_a_one_line_warning(tmp_path):
    ply = textured_ply(tmp_path / "fuze.ply")
    out = tmp_path / "x.png"
    common = ["-m", "refraster.cli", "render", ply, "--out", out, "--width", "32",
              "--height", "24"]
    quiet = _run(*common, "-q")
    assert quiet.returncode == 0 and quiet.stderr == "", quiet.stderr
    plain = _run(*common)
    assert plain.returncode == 0, plain.stderr
    lines = plain.stderr.strip().splitlines()
    assert lines[0] == ("refraster: warning: trimesh.util: unable to load image! "
                        "(FileNotFoundError: missing_texture.png)"), plain.stderr
    assert len(lines) == 2 and lines[1].startswith("wrote "), plain.stderr
    debug = _run(*common, "--debug")
    assert debug.returncode == 0 and "Traceback" in debug.stderr
    assert "FileNotFoundError: missing_texture.png" in debug.stderr


def test_missing_texture_in_a_golden_scene_is_a_one_line_warning(tmp_path):
    textured_ply(tmp_path / "part.ply")
    toml = tmp_path / "part.toml"
    toml.write_text('[viewport]\nwidth = 32\nheight = 24\n[[draw]]\nmesh = "part.ply"\n')
    proc = _run("-m", "refraster.golden.cli", "generate", "--out", tmp_path / "g",
                "--scene-file", toml)
    assert proc.returncode == 0, proc.stderr
    warnings = [ln.split("\r")[-1] for ln in proc.stderr.splitlines() if "warning" in ln]
    assert warnings == ["refraster: warning: trimesh.util: unable to load image! "
                        "(FileNotFoundError: missing_texture.png)"], proc.stderr
    assert "Traceback" not in proc.stderr


# --- 6. clip coordinates that overflow float32, a singular projection -----------------------------

def test_overflowing_clip_coordinates_and_singular_projection_are_errors():
    import refraster
    from refraster.camera import look_at, perspective
    box = trimesh.creation.box()
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    view, proj = look_at((3.0, 2.0, 4.0), (0.0, 0.0, 0.0)), perspective(40.0, 4 / 3, 1.0, 20.0)
    kw = dict(view=view, proj=proj, width=32, height=24)
    assert (refraster.render((v, f), **kw).prim_id >= 0).any()
    with pytest.raises(ValueError, match=r"meshes\[0\]: clip coordinates overflow .* float32"):
        refraster.render((v * 1e300, f), **kw)
    with pytest.raises(ValueError, match=r"meshes\[1\]: clip coordinates overflow"):
        refraster.render([(v, f), (v * 1e300, f)], **kw)
    refraster.render((v * 1e300, f), raster=RasterState(precision="float64"), **kw)   # fits float64
    with pytest.raises(ValueError, match=r"meshes\[0\]: clip coordinates overflow .* float64"):
        refraster.render((v * 1e300, f), raster=RasterState(precision="float64"),
                         model=np.diag([1e10, 1e10, 1e10, 1.0]), **kw)
    with pytest.raises(ValueError, match="proj is singular"):
        refraster.render((v, f), view=view, proj=np.zeros((4, 4)), width=32, height=24)
    flat = proj.copy()
    flat[3] = flat[2]                    # w = z: every point on one plane
    with pytest.raises(ValueError, match="proj is singular"):
        refraster.render((v, f), view=view, proj=flat, width=32, height=24)


def test_stl_at_float32_limits_is_one_line(tmp_path, capsys):
    box = trimesh.creation.box()
    box.vertices = np.asarray(box.vertices) * 6e38          # ±3e38: finite in float32
    path = tmp_path / "huge.stl"
    box.export(path)
    assert cli.main(["render", str(path), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"refraster: error: mesh file '{path}': "), err
    assert "overflow" in err[0] and not (tmp_path / "x.png").exists()


def test_oracle_scenes_at_1e30_still_render():
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    import refraster
    from oracles.scenes import random_scene
    for index in (9, 22):
        sc = random_scene(index)
        assert sc.name.endswith("huge_1e30")
        for precision in ("float32", "float64"):
            fb = refraster.render(sc.meshes, view=sc.view, proj=sc.proj, width=sc.width,
                                  height=sc.height, raster=RasterState(precision=precision))
            assert (fb.prim_id >= 0).sum() > 0


def test_vertex_stage_counts_the_clip_coordinates_that_are_not_finite():
    """The vertex stage's count is what lets ``_check_clip`` skip its look at every
    coordinate: one inf (or nan) coordinate counts one, in either precision."""
    from refraster.raster.primitive import transform_counted
    v = np.array([[0.0, 0.0, 0.0], [1e300, 0.0, 0.0], [np.nan, 0.0, 0.0], [1.0, 2.0, 3.0]])
    m = np.eye(4)
    assert transform_counted(v[[0, 3]], m, "float32")[1] == 0
    # float32: 1e300 becomes inf, so 0·inf makes y, z, w nan too; the nan vertex: all four
    assert transform_counted(v, m, "float32")[1] == 8
    m64 = np.diag([1e10, 1.0, 1.0, 1.0])
    assert transform_counted(v[[0, 1, 3]], np.eye(4), "float64")[1] == 0
    # float64: only x overflows (1e310); the nan vertex's four coordinates are nan
    assert transform_counted(v, m64, "float64")[1] == 5


def test_clip_check_sums_first_and_looks_again_when_the_sum_overflows():
    """``_check_clip`` sums the clip coordinates first (finite only if every one is); finite
    coordinates whose sum overflows float64 are looked at one by one and pass; an inf or a nan
    anywhere is refused whatever the others."""
    import refraster
    from refraster.raster import _check_clip
    box = refraster.as_mesh(trimesh.creation.box())
    big = np.full((8, 4), 1.5e308)
    _check_clip(big, [box], "float64")                       # sum inf, every value finite
    for bad in (np.inf, -np.inf, np.nan):
        c = big.copy()
        c[5, 2] = bad
        with pytest.raises(ValueError, match=r"meshes\[0\]: clip coordinates overflow"):
            _check_clip(c, [box], "float64")
        c = np.ones((8, 4))
        c[7, 3] = bad
        with pytest.raises(ValueError, match=r"vertex 7"):
            _check_clip(c, [box], "float64")
