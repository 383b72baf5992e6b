"""Re-export of :mod:`refraster.clipsurface.capping` (moved into the clip-surface package;
this name stays importable)."""

from .clipsurface.capping import (CAP_STYLES, FOOTPRINT_MARGIN, MAX_CAP_VERTICES,  # noqa: F401
                                  SURE_EXTRAPOLATION, __all__, cap_mesh,
                                  check_watertight, cull_cap, exact_caps, light_caps,
                                  pixel_rays, shade_cap_pixels, shade_caps, solid_texture,
                                  surely_inside, texture_caps)
