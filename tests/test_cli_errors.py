"""Every failure of the command line is one line naming the real cause, exit 2, whichever entry
point; third-party log records are one-line warnings, in full only with --debug (issue 18)."""

import subprocess
import sys

import numpy as np
import pytest
import trimesh

from refraster import cli

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
