"""The option values of render_halos (refraster.halos4d.options): every bad field is refused
when the value is made, with one line that names it; the defaults are render_halos' own."""

import dataclasses

import numpy as np
import pytest

import refraster.halos4d as h
from refraster.halos4d import HaloStyle, Halos, View4D
from refraster.halos4d.options import AMBIENT
from option_values import assert_refused_with_one_line

#: (value class, field, bad value, exception, the error's first words)
BAD = [
    (View4D, "rotation", np.eye(3), ValueError, "view.rotation must have shape (4, 4)"),
    (View4D, "rotation", 2 * np.eye(4), ValueError, "view.rotation must be orthogonal"),
    (View4D, "rotation", np.full((4, 4), np.nan), ValueError, "view.rotation contains 16"),
    (View4D, "projection", "fisheye", ValueError, "view.projection must be one of"),
    (View4D, "projection", None, TypeError, "view.projection must be a str"),
    (View4D, "eye", float("nan"), ValueError, "view.eye must be finite"),
    (View4D, "eye", "far", TypeError, "view.eye must be a real number"),
    (View4D, "scale", 0.0, ValueError, "view.scale must be > 0"),
    (View4D, "margin", -0.1, ValueError, "view.margin must be >= 0"),
    (View4D, "margin", 11.0, ValueError, "view.margin must be <= 10"),
    (View4D, "stereo", True, TypeError, "view.stereo must be None or the angle between the eyes"),
    (View4D, "stereo", 91.0, ValueError, "view.stereo must be <= 90"),
    (View4D, "stereo", -6.0, ValueError, "view.stereo must be >= 0"),
    (Halos, "enabled", 1, TypeError, "halos.enabled must be a bool"),
    (Halos, "rho", 0.0, ValueError, "halos.rho must be > 0"),
    (Halos, "rho", float("nan"), ValueError, "halos.rho must be finite"),
    (Halos, "delta_d", -1.0, ValueError, "halos.delta_d must be >= 0"),
    (Halos, "delta_t", 1.5, ValueError, "halos.delta_t must be <= 1"),
    (Halos, "delta_t", None, TypeError, "halos.delta_t must be a real number"),
    (Halos, "surface_width", 0.0, ValueError, "halos.surface_width must be > 0"),
    (Halos, "surface_width", 1.2, ValueError, "halos.surface_width must be <= 1"),
    (Halos, "antialias", 0.5, ValueError, "halos.antialias must be <= 0.3"),
    (Halos, "antialias", -0.1, ValueError, "halos.antialias must be >= 0"),
    (Halos, "depth_eps", -1e-9, ValueError, "halos.depth_eps must be >= 0"),
    (HaloStyle, "opacity", 0.0, ValueError, "style.opacity must be > 0"),
    (HaloStyle, "opacity", 1.1, ValueError, "style.opacity must be <= 1"),
    (HaloStyle, "ambient", 1.5, ValueError, "style.ambient must be <= 1"),
    (HaloStyle, "halo_color", (1, 1), ValueError, "style.halo_color must have shape (3)"),
    (HaloStyle, "halo_color", None, TypeError, "style.halo_color must be a numeric array"),
    (HaloStyle, "halo_opacity", 1.0, ValueError, "style.halo_opacity must be < 1"),
    (HaloStyle, "halo_opacity", -0.1, ValueError, "style.halo_opacity must be >= 0"),
    (HaloStyle, "boundary_color", (0, 1, np.nan), ValueError, "style.boundary_color contains 1"),
    (HaloStyle, "boundary_width", 0.0, ValueError, "style.boundary_width must be > 0"),
    (HaloStyle, "boundary_width", 1.0, ValueError, "style.boundary_width must be < 1"),
]


@pytest.mark.parametrize("cls, name, bad, exc, words", BAD,
                         ids=[f"{c.__name__}.{n}-{i}" for i, (c, n, _, _, _) in enumerate(BAD)])
def test_a_bad_field_is_refused_with_one_line_naming_it(cls, name, bad, exc, words):
    assert_refused_with_one_line(cls, name, bad, exc, words)


def test_perspective_needs_a_positive_eye():
    View4D(eye=-2.0)                       # orthographic: the eye only offsets the 4D depth
    with pytest.raises(ValueError, match=r"^view\.eye must be positive under perspective"):
        View4D(projection="perspective", eye=-2.0)


def test_defaults_are_render_halos_own():
    v, hl, st = View4D(), Halos(), HaloStyle()
    assert (v.rotation, v.projection, v.eye, v.scale, v.margin, v.stereo) == (
        None, "orthographic", None, 1.0, 0.05, None)
    assert (hl.enabled, hl.rho, hl.delta_d, hl.delta_t, hl.surface_width, hl.antialias,
            hl.depth_eps) == (True, None, None, 0.3, 0.3, None, None)
    assert (st.opacity, st.ambient, st.halo_color, st.halo_opacity, st.boundary_color,
            st.boundary_width) == (0.9, AMBIENT, (0.5, 0.5, 0.5), 0.0, None, 0.15)
    assert h.STEREO_ANGLE == 6.0


def test_values_are_immutable_normalized_and_compare():
    rot = h.compose(("zx", 0.5), ("yz", -1.0))
    v = View4D(rotation=rot, projection="Perspective", stereo=6)
    assert v.rotation == tuple(tuple(row) for row in rot.tolist())
    assert np.array_equal(np.array(v.rotation), rot)
    assert v.projection == "perspective" and v.stereo == 6.0
    assert v == View4D(rotation=rot.tolist(), projection="perspective", stereo=6.0)
    assert hash(v) == hash(v.replace())
    assert HaloStyle(boundary_color=np.array([0, 1, 0])).boundary_color == (0.0, 1.0, 0.0)
    assert Halos(rho=1).rho == 1.0 and isinstance(Halos(rho=1).rho, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.margin = 0.1
    with pytest.raises(dataclasses.FrozenInstanceError):
        Halos().enabled = False
