"""Independent oracles for the tests and benchmarks.

``llvmpipe``: Mesa's conformant CPU OpenGL driver, driven through moderngl on headless EGL.
``scenes``: seeded random scenes (meshes, cameras, viewport sizes) to compare refraster with it.

Import ``llvmpipe`` through the ``oracle`` fixture (``oracle("oracles.llvmpipe")``): the import
creates the GL context and raises :class:`oracles.llvmpipe.LlvmpipeUnavailable` when it cannot,
so the test skips locally and fails under ``CI=true``.
"""
