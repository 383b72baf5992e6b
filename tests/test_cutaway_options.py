"""The option values of render_cutaway (refraster.cutaway.options): every bad field is refused
when the value is made, with one line that names it; the defaults are the paper's choices."""

import dataclasses
import math

import numpy as np
import pytest

from refraster.cutaway import CutSurfaces, Cutaway, GhostLines
from refraster.cutaway.surface import FLOOR_MARGIN
from option_values import assert_refused_with_one_line

#: (value class, field, bad value, exception, the error's first words)
BAD = [
    (Cutaway, "angle", 0.0, ValueError, "cutaway.angle must lie in (0, π/2)"),
    (Cutaway, "angle", math.pi / 2, ValueError, "cutaway.angle must lie in (0, π/2)"),
    (Cutaway, "angle", [0.3, -1.0], ValueError, "cutaway.angle must lie in (0, π/2)"),
    (Cutaway, "angle", float("nan"), ValueError, "cutaway.angle must be finite"),
    (Cutaway, "angle", [[0.3]], ValueError, "cutaway.angle must be a scalar or a non-empty"),
    (Cutaway, "angle", [], ValueError, "cutaway.angle must be a scalar or a non-empty"),
    (Cutaway, "angle", True, TypeError, "cutaway.angle must be a real number"),
    (Cutaway, "angle", "wide", TypeError, "cutaway.angle must be a numeric array"),
    (Cutaway, "variant", "fast", ValueError, "cutaway.variant must be one of"),
    (Cutaway, "variant", 1, TypeError, "cutaway.variant must be a str"),
    (Cutaway, "perspective_compensation", 1, TypeError,
     "cutaway.perspective_compensation must be a bool"),
    (Cutaway, "edge_compression", -0.1, ValueError, "cutaway.edge_compression must be >= 0"),
    (Cutaway, "edge_compression", "on", TypeError, "cutaway.edge_compression must be a real"),
    (Cutaway, "floor_normal", (0, 0, 0), ValueError, "cutaway.floor_normal must not be zero"),
    (Cutaway, "floor_normal", (0, 1), ValueError, "cutaway.floor_normal must have shape (3)"),
    (Cutaway, "floor_normal", (0, np.inf, 0), ValueError, "cutaway.floor_normal contains 1"),
    (Cutaway, "floor_margin", -0.01, ValueError, "cutaway.floor_margin must be >= 0"),
    (Cutaway, "floor_margin", 2.0, ValueError, "cutaway.floor_margin must be <="),
    (Cutaway, "buffer_size", 8, TypeError, "cutaway.buffer_size must be None or a (width, "
                                           "height) pair"),
    (Cutaway, "buffer_size", (0, 8), ValueError, "cutaway.buffer_size: width must be positive"),
    (Cutaway, "buffer_size", (8, 2.5), TypeError, "cutaway.buffer_size: height must be an int"),
    (CutSurfaces, "shade", "yes", TypeError, "cut_surfaces.shade must be a bool"),
    (CutSurfaces, "color", (1, 0), ValueError, "cut_surfaces.color must have shape (3)"),
    (CutSurfaces, "color", "red", TypeError, "cut_surfaces.color must be a numeric array"),
    (CutSurfaces, "dilation", None, TypeError, "cut_surfaces.dilation must be a bool"),
    (CutSurfaces, "outlines", 0, TypeError, "cut_surfaces.outlines must be a bool"),
    (GhostLines, "source", "edges", ValueError, "ghosts.source must be one of"),
    (GhostLines, "distance", 0.0, ValueError, "ghosts.distance must be > 0, got 0.0 (ghosts=None"),
    (GhostLines, "distance", -1.0, ValueError, "ghosts.distance must be >= 0"),
    (GhostLines, "distance", float("inf"), ValueError, "ghosts.distance must be finite"),
    (GhostLines, "fade", 1.0, TypeError, "ghosts.fade must be a bool"),
    (GhostLines, "crease_angle", 200.0, ValueError, "ghosts.crease_angle must be <= 180"),
    (GhostLines, "crease_angle", -1, ValueError, "ghosts.crease_angle must be >= 0"),
]


@pytest.mark.parametrize("cls, name, bad, exc, words", BAD,
                         ids=[f"{c.__name__}.{n}={b!r}" for c, n, b, _, _ in BAD])
def test_a_bad_field_is_refused_with_one_line_naming_it(cls, name, bad, exc, words):
    assert_refused_with_one_line(cls, name, bad, exc, words)


def test_defaults_are_the_papers_choices():
    c = Cutaway()
    assert (c.angle, c.variant, c.perspective_compensation, c.edge_compression, c.floor_normal,
            c.floor_margin, c.buffer_size) == (math.pi / 6, "jfa", True, 0.1, None,
                                               FLOOR_MARGIN, None)
    assert CutSurfaces() == CutSurfaces(shade=True, color=None, dilation=True, outlines=True)
    assert GhostLines() == GhostLines(source="lines", distance=None, fade=True, crease_angle=30.0)


def test_every_entry_floods_with_the_papers_schedule_by_default():
    """The paper's jump flooding (Rong & Tan, log n passes: ``"jfa"``) is the default of the
    option value, of ``cutaway_surface`` and of a golden package that stores no variant (the
    GL backend); ``"jfa+1"`` is a named option."""
    import inspect

    from refraster.cutaway import cutaway_surface
    from refraster.cutaway.render import DEFAULT_CUTAWAY
    from refraster.gl.cutaway import options

    assert DEFAULT_CUTAWAY.variant == "jfa"
    assert inspect.signature(cutaway_surface).parameters["variant"].default == "jfa"
    package = {"draws": [{"name": "a"}, {"name": "b"}],
               "parameters": {"angle": 0.5, "interest": ["a"], "secondary": ["b"]}}
    assert options(package)[0]["variant"] == "jfa"
    assert Cutaway(variant="jfa+1").variant == "jfa+1"


def test_values_are_immutable_normalized_and_compare():
    c = Cutaway(angle=np.array([0.3, 0.4]), floor_normal=np.array([0, 1, 0]),
                buffer_size=[32, 24], variant="JFA")
    assert c.angle == (0.3, 0.4) and c.floor_normal == (0.0, 1.0, 0.0)
    assert c.buffer_size == (32, 24) and c.variant == "jfa"
    assert Cutaway(angle=np.float32(0.5)).angle == float(np.float32(0.5))
    assert isinstance(Cutaway(angle=1).angle, float)
    assert c == Cutaway(angle=[0.3, 0.4], floor_normal=(0.0, 1.0, 0.0), buffer_size=(32, 24),
                        variant="jfa")
    assert hash(c) == hash(c.replace())
    assert CutSurfaces(color=[1, 0, 0]).color == (1.0, 0.0, 0.0)
    assert GhostLines(source="Visible", distance=2).source == "visible"
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.angle = 0.2
    with pytest.raises(dataclasses.FrozenInstanceError):
        GhostLines().distance = 1.0


def test_an_option_of_the_wrong_type_is_refused_by_its_public_name():
    from refraster._validate import as_option
    from refraster.halos4d import Halos
    with pytest.raises(TypeError, match=r"^cutaway must be a refraster\.cutaway\.Cutaway, got dict$"):
        as_option({}, Cutaway, "cutaway")
    with pytest.raises(TypeError, match=r"^ghosts must be a refraster\.cutaway\.GhostLines \(or None\)"):
        as_option(1, GhostLines, "ghosts", optional=True)
    with pytest.raises(TypeError, match=r"^halos must be a refraster\.halos4d\.Halos, got Cutaway$"):
        as_option(Cutaway(), Halos, "halos")
    assert as_option(None, GhostLines, "ghosts", optional=True) is None
