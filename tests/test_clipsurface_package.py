"""The clip-surface package: every name importable from where it was before the package
existed (refraster.clipsurface, .capping, .offsetmaps). Its imports (no circle, the core never
imports it) are checked with every other module's in tests/test_architecture.py."""

import importlib

import pytest

OLD_NAMES = {
    "refraster.clipsurface": ["ClipSurface", "ReliefClipPlane", "ClippedFramebuffer",
                              "as_surfaces", "clip_function", "clip_mask", "render_clipped",
                              "clipped_at", "ORTHOGONALITY_TOLERANCE"],
    "refraster.capping": ["CAP_STYLES", "check_watertight", "cap_mesh", "cull_cap",
                          "exact_caps", "light_caps", "shade_cap_pixels", "shade_caps",
                          "solid_texture", "surely_inside", "MAX_CAP_VERTICES",
                          "FOOTPRINT_MARGIN", "SURE_EXTRAPOLATION", "pixel_rays",
                          "texture_caps"],
    "refraster.offsetmaps": ["WRAP_MODES", "as_offset_map", "load_offset_map", "sample",
                             "constant", "value_noise", "perlin_noise", "ragged_cut",
                             "sinusoid", "steps", "blend", "normal_map", "encode_normal_map",
                             "occlusion_map", "as_wrap", "bilinear_taps", "bilinear",
                             "texture2d_flat"],
}


@pytest.mark.parametrize("module", sorted(OLD_NAMES))
def test_every_old_name_is_importable_from_its_old_place(module):
    mod = importlib.import_module(module)
    for name in OLD_NAMES[module] + list(getattr(mod, "__all__", [])):
        assert hasattr(mod, name), f"{module}.{name}"


def test_the_shims_are_the_package_modules_objects():
    from refraster import capping, offsetmaps
    from refraster.clipsurface import capping as c2
    from refraster.clipsurface import offsetmaps as o2
    assert capping.cap_mesh is c2.cap_mesh and offsetmaps.sample is o2.sample
    assert capping.__all__ == c2.__all__ and offsetmaps.__all__ == o2.__all__
