"""What the lavapipe oracles (:mod:`oracles.lavapipe`, :mod:`oracles.lavapipe_msaa`) share: Mesa's
lavapipe found through wgpu-py, one device, the clip-position vertex stage and its vertex data.

Written against wgpu-py alone: the oracles judge refraster and its backends from outside, so
nothing here imports refraster (its WebGPU backend ``refraster.wgpu`` finds the same adapter and
needs the same wgpu-py work-around, each written again there on purpose).

* :data:`WGPU`, :data:`ADAPTER`, :data:`DEVICE` — made on import; the adapter must be Mesa's CPU
  one (``llvmpipe`` on Vulkan) and offer ``depth-clip-control``; the device keeps wgpu-py's own
  limits (the oracles render a few small targets). :class:`LavapipeUnavailable` otherwise, so the
  oracles are reached through ``conftest.require``.
* :func:`vertex_wgsl` — ``VIn``/``VOut``/``vs``: the vertex position is the clip position as given
  (float32, de-indexed), with the clip y negated under ``ndc_y="down"`` (Vulkan's NDC through
  WebGPU, whose NDC y points up); the face's global index reaches the fragment flat.
* :data:`VERTEX_BUFFER`, :func:`vertex_data` — that vertex (clip ``float32x4``, face ``sint32``;
  20 bytes) as a buffer layout and as data from a list of draws.
* :func:`unclipped_depth` — wgpu-py 0.32 drops ``primitive.unclipped_depth``; set it in the C
  struct for the ``with`` body.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

__all__ = ["LavapipeUnavailable", "WGPU", "ADAPTER", "DEVICE", "VERTEX_BUFFER", "vertex_wgsl",
           "vertex_data", "unclipped_depth", "renderer"]


class LavapipeUnavailable(RuntimeError):
    """wgpu or lavapipe is missing, or the adapter found is not Mesa's CPU one."""


def _device():
    try:
        import wgpu
    except ImportError as exc:
        raise LavapipeUnavailable(f"wgpu is not installed ({exc})") from None
    try:
        found = wgpu.gpu.request_adapter_sync(power_preference="low-power")
    except Exception as exc:       # no Vulkan driver at all
        raise LavapipeUnavailable(f"no WebGPU adapter (apt-get install mesa-vulkan-drivers): "
                                  f"{exc}") from None
    if found is None:
        raise LavapipeUnavailable("no WebGPU adapter (apt-get install mesa-vulkan-drivers)")
    info = found.info
    if "llvmpipe" not in str(info.get("device", "")) or info.get("backend_type") != "Vulkan":
        raise LavapipeUnavailable(f"the WebGPU adapter is not lavapipe: {info.get('device')!r} "
                                  f"on {info.get('backend_type')!r}")
    if "depth-clip-control" not in found.features:
        raise LavapipeUnavailable("lavapipe does not expose depth-clip-control")
    return wgpu, found, found.request_device_sync(required_features=["depth-clip-control"])


WGPU, ADAPTER, DEVICE = _device()


def renderer():
    """The adapter's device and driver description (for reports)."""
    info = ADAPTER.info
    return f"{info.get('device')} ({info.get('description')}) via wgpu {WGPU.__version__}"


_VERTEX = """
struct VIn { @location(0) clip: vec4<f32>, @location(1) face: i32 };
struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) face: i32,
};
@vertex fn vs(v: VIn) -> VOut {
    var o: VOut;
    // ndc_y = "down" (Vulkan) through WebGPU, whose NDC y points up: the clip y negated
    o.pos = vec4<f32>(v.clip.x, YSIGN * v.clip.y, v.clip.z, v.clip.w);
    o.face = v.face;
    return o;
}
"""


def vertex_wgsl(ndc_y):
    """The vertex stage's WGSL (``VIn``, ``VOut``, ``vs``) for ``ndc_y`` ``"up"`` or ``"down"``;
    a fragment stage written after it reads ``VOut.face``."""
    return _VERTEX.replace("YSIGN", "-1.0" if ndc_y == "down" else "1.0")


#: The vertex of :func:`vertex_wgsl` as a WebGPU vertex buffer layout.
VERTEX_BUFFER = {"array_stride": 20, "attributes": [
    {"format": "float32x4", "offset": 0, "shader_location": 0},
    {"format": "sint32", "offset": 16, "shader_location": 1}]}


def vertex_data(draws):
    """``draws`` (a list of ``(clip (V, 4) float32, faces (F, 3))``, in order) de-indexed: one
    vertex per triangle corner carrying its face's global index (draw calls in order) →
    ``(structured array of 3·F vertices, F)``."""
    clip = np.concatenate([np.asarray(c, np.float32)[np.asarray(f, np.int64)].reshape(-1, 4)
                           for c, f in draws]) if draws else np.zeros((0, 4), np.float32)
    n_faces = len(clip) // 3
    data = np.zeros(3 * n_faces, dtype=[("c", "<f4", 4), ("f", "<i4")])
    data["c"] = clip
    data["f"] = np.repeat(np.arange(n_faces, dtype=np.int32), 3)
    return data, n_faces


@contextmanager
def unclipped_depth(enabled=True):
    """For the ``with`` body, pipelines are created with ``unclippedDepth = 1`` in wgpu-native's
    ``WGPUPrimitiveState`` (WebGPU's ``GPUPrimitiveState.unclippedDepth``; needs
    ``depth-clip-control``): wgpu-py 0.32's ``_api.py`` marks the field "not used" and never sets
    it. ``enabled=False`` changes nothing."""
    if not enabled:
        yield
        return
    from wgpu.backends.wgpu_native import _api
    real = _api.new_struct

    def patched(ctype, **fields):
        if ctype == "WGPUPrimitiveState":
            fields["unclippedDepth"] = 1
        return real(ctype, **fields)

    _api.new_struct = patched
    try:
        yield
    finally:
        _api.new_struct = real
