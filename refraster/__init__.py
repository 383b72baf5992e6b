"""refraster — a CPU reference rasterizer for illustrative-rendering techniques."""

from importlib.metadata import PackageNotFoundError, version as _version

from . import camera
from .camera import Camera, look_at, orthographic, perspective, frustum
from .framebuffer import Framebuffer, normalized_linear_depth, render
from .mesh import Mesh, as_mesh
from .raster import Fragments, Resolved, concat, draw, rasterize, resolve
from .raster.state import RasterState
from .multisample import SampleFramebuffer, render_samples, resolve_color, resolve_samples
from .sample_rate import GBufferSampling

try:
    __version__ = _version("refraster")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.1.0"

__all__ = [
    "render", "draw", "rasterize", "resolve", "concat", "RasterState", "Framebuffer", "Fragments", "Resolved",
    "normalized_linear_depth", "Mesh", "as_mesh", "Camera", "camera", "look_at", "perspective",
    "frustum", "orthographic", "__version__", "render_samples", "resolve_color",
    "resolve_samples", "SampleFramebuffer", "GBufferSampling",
]
