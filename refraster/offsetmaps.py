"""Re-export of :mod:`refraster.clipsurface.offsetmaps` (moved into the clip-surface package;
this name stays importable)."""

from .clipsurface.offsetmaps import (WRAP_MODES, __all__, as_offset_map, as_wrap,  # noqa: F401
                                     bilinear, bilinear_taps, blend, constant,
                                     encode_normal_map, load_offset_map, normal_map,
                                     occlusion_map, perlin_noise, ragged_cut, sample, sinusoid,
                                     steps, texture2d_flat, value_noise)
