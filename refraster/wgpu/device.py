"""The WebGPU device of refraster.wgpu: an adapter, a device created with **WebGPU's default
limits** and only the optional features asked for by name, and the one wgpu-py work-around it
needs (the lavapipe oracles, ``tests/oracles/_vulkan.py``, write their own: they do not import
the backend they judge).

WebGPU guarantees a set of default limits on every device (the WebGPU specification, "Limits");
an adapter may offer more (lavapipe grants 128 bytes per sample across the colour targets where
the default is 32), but a device gets more only when it asks. wgpu-py asks for every limit the
adapter has unless told otherwise, so :func:`create_device` passes :data:`DEFAULT_LIMITS`
explicitly: a frame that renders on this device renders on any conformant WebGPU implementation.
"""

from __future__ import annotations

__all__ = ["WGPUUnavailable", "DEFAULT_LIMITS", "OPTIONAL_FEATURES", "adapter", "create_device",
           "unclipped_depth", "describe"]


class WGPUUnavailable(RuntimeError):
    """wgpu-py is missing, there is no WebGPU adapter, or a feature asked for is missing."""


#: WebGPU's default limits (the specification's "Limits" table, the values every conformant
#: implementation supports); :func:`create_device` asks for exactly these.
DEFAULT_LIMITS = {
    "max-texture-dimension-1d": 8192,
    "max-texture-dimension-2d": 8192,
    "max-texture-dimension-3d": 2048,
    "max-texture-array-layers": 256,
    "max-bind-groups": 4,
    "max-bind-groups-plus-vertex-buffers": 24,
    "max-bindings-per-bind-group": 1000,
    "max-dynamic-uniform-buffers-per-pipeline-layout": 8,
    "max-dynamic-storage-buffers-per-pipeline-layout": 4,
    "max-sampled-textures-per-shader-stage": 16,
    "max-samplers-per-shader-stage": 16,
    "max-storage-buffers-per-shader-stage": 8,
    "max-storage-textures-per-shader-stage": 4,
    "max-uniform-buffers-per-shader-stage": 12,
    "max-uniform-buffer-binding-size": 65536,
    "max-storage-buffer-binding-size": 134217728,
    "min-uniform-buffer-offset-alignment": 256,
    "min-storage-buffer-offset-alignment": 256,
    "max-vertex-buffers": 8,
    "max-buffer-size": 268435456,
    "max-vertex-attributes": 16,
    "max-vertex-buffer-array-stride": 2048,
    "max-inter-stage-shader-variables": 16,
    "max-color-attachments": 8,
    "max-color-attachment-bytes-per-sample": 32,
    "max-compute-workgroup-storage-size": 16384,
    "max-compute-invocations-per-workgroup": 256,
    "max-compute-workgroup-size-x": 256,
    "max-compute-workgroup-size-y": 256,
    "max-compute-workgroup-size-z": 64,
    "max-compute-workgroups-per-dimension": 65535,
}

#: Optional features refraster.wgpu may ask for, each by name and only when used.
OPTIONAL_FEATURES = {
    "depth-clip-control": "WebGPU's unclippedDepth: scenes with raster.depth_clamp = true",
    "primitive-index": "@builtin(primitive_index): only the cross-check of the face ids "
                       "(tests/test_wgpu_backend.py)",
}


def adapter(*, require_lavapipe=False):
    """``(wgpu module, adapter)``; raises :class:`WGPUUnavailable`. ``require_lavapipe``: the
    adapter must be Mesa's CPU one (llvmpipe through Vulkan)."""
    try:
        import wgpu
    except ImportError as exc:
        raise WGPUUnavailable(f"wgpu is not installed ({exc}); install the 'wgpu' extra: "
                              "pip install refraster[wgpu]") from None
    try:
        found = wgpu.gpu.request_adapter_sync(power_preference="low-power")
    except Exception as exc:       # no Vulkan/Metal/D3D12 driver at all
        raise WGPUUnavailable(f"no WebGPU adapter (for Mesa's lavapipe: apt-get install "
                              f"mesa-vulkan-drivers): {exc}") from None
    if found is None:
        raise WGPUUnavailable("no WebGPU adapter (for Mesa's lavapipe: apt-get install "
                              "mesa-vulkan-drivers)")
    info = found.info
    if require_lavapipe and ("llvmpipe" not in str(info.get("device", ""))
                             or info.get("backend_type") != "Vulkan"):
        raise WGPUUnavailable(f"the WebGPU adapter is not lavapipe: {info.get('device')!r} on "
                              f"{info.get('backend_type')!r}")
    return wgpu, found


def create_device(found, features=(), limits=None):
    """A device of adapter ``found`` with :data:`DEFAULT_LIMITS` (updated with ``limits``, a
    dict of raised limits asked for by name) and the optional ``features`` (names of
    :data:`OPTIONAL_FEATURES`). Raises :class:`WGPUUnavailable` when the adapter lacks one."""
    missing = [f for f in features if f not in found.features]
    if missing:
        raise WGPUUnavailable(f"the adapter does not offer feature(s) {missing}")
    wanted = dict(DEFAULT_LIMITS)
    wanted.update(limits or {})
    # a limit this wgpu-py does not know (an older or newer table) is left to its default
    known = set(found.limits.keys())
    wanted = {k: v for k, v in wanted.items() if k in known}
    return found.request_device_sync(required_features=list(features), required_limits=wanted)


def describe(found, wgpu):
    """The adapter's device and driver (for reports and candidate markers)."""
    info = found.info
    return (f"{info.get('device')} ({info.get('description')}; {info.get('backend_type')}) via "
            f"wgpu-py {wgpu.__version__}")


class unclipped_depth:
    """wgpu-py 0.32 does not pass ``primitive.unclipped_depth`` on to wgpu-native (its
    ``_api.py`` marks ``unclippedDepth`` "not used"): for the ``with`` body, the struct it
    builds for the primitive state gets ``unclippedDepth = 1`` (the C field of WebGPU's
    ``GPUPrimitiveState.unclippedDepth``; the device needs ``depth-clip-control``).
    ``enabled=False`` changes nothing."""

    def __init__(self, enabled=True):
        self.enabled = enabled

    def __enter__(self):
        if not self.enabled:
            return None
        from wgpu.backends.wgpu_native import _api
        self.api, self.real = _api, _api.new_struct

        def new_struct(ctype, **kwargs):
            if ctype == "WGPUPrimitiveState":
                kwargs["unclippedDepth"] = 1
            return self.real(ctype, **kwargs)

        _api.new_struct = new_struct
        return None

    def __exit__(self, *exc):
        if self.enabled:
            self.api.new_struct = self.real
        return False
