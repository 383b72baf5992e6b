"""llvmpipe's G-buffer pass, timed in a process of its own (run by benchmarks/raster.py).

The same job as ``refraster.render``'s G-buffer: depth (32-bit float), eye-space normal
(RGBA32F, flat, from screen derivatives of the eye position; with ``normals`` in the scene
file, interpolated from them), primitive id and facing (RG32I),
depth test LESS. Timed per frame: draw + ``glFinish`` + read-back of every target into reused
arrays, the mesh resident in a VBO. ``LP_NUM_THREADS`` and ``GLIBC_TUNABLES`` are set by the
parent before this process starts (``../shared/LLVMPIPE.md``).

    python -m benchmarks._gl_gbuffer SCENE.npz --repeats 15   → prints JSON on stdout
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

VS = """
#version 330
uniform mat4 mvp;
uniform mat4 mv;
in vec3 in_pos;
out vec3 v_eye;
void main() {
    v_eye = (mv * vec4(in_pos, 1.0)).xyz;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""
#: With vertex normals in the scene (``benchmarks.raster --normals smooth``): the eye-space
#: normal interpolated from them and renormalized, as refraster's ``normals="smooth"``.
VS_SMOOTH = """
#version 330
uniform mat4 mvp;
uniform mat4 mv;
in vec3 in_pos;
in vec3 in_normal;
out vec3 v_n;
void main() {
    v_n = mat3(mv) * in_normal;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""
FS_SMOOTH = """
#version 330
in vec3 v_n;
layout(location = 0) out vec4 out_normal;
layout(location = 1) out ivec2 out_id;
void main() {
    out_normal = vec4(normalize(v_n), 1.0);
    out_id = ivec2(gl_PrimitiveID, gl_FrontFacing ? 1 : 0);
}
"""
FS = """
#version 330
in vec3 v_eye;
layout(location = 0) out vec4 out_normal;
layout(location = 1) out ivec2 out_id;
void main() {
    vec3 n = normalize(cross(dFdx(v_eye), dFdy(v_eye)));
    out_normal = vec4(n, 1.0);
    out_id = ivec2(gl_PrimitiveID, gl_FrontFacing ? 1 : 0);
}
"""


#: Frames drawn before timing (the first one is reported as first_ms), as in benchmarks.raster.
WARMUP = 3


def run(path, repeats):
    import moderngl

    with np.load(path, allow_pickle=False) as z:
        vertices = z["vertices"].astype(np.float32)
        faces = z["faces"].astype(np.int32)
        mvp = z["mvp"].astype(np.float32)
        mv = z["mv"].astype(np.float32)
        w, h = int(z["width"]), int(z["height"])
        normals = z["normals"].astype(np.float32) if "normals" in z.files else None
    ctx = moderngl.create_standalone_context(backend="egl")
    if normals is None:
        prog = ctx.program(vertex_shader=VS, fragment_shader=FS)
    else:
        prog = ctx.program(vertex_shader=VS_SMOOTH, fragment_shader=FS_SMOOTH)
    prog["mvp"].write(mvp.T.copy().tobytes())
    prog["mv"].write(mv.T.copy().tobytes())
    ibo = ctx.buffer(faces.tobytes())
    if normals is None:
        vbo = ctx.buffer(vertices.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f", "in_pos")], ibo, index_element_size=4)
    else:
        vbo = ctx.buffer(np.hstack([vertices, normals]).tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "in_pos", "in_normal")], ibo,
                               index_element_size=4)
    normal = ctx.texture((w, h), 4, dtype="f4")
    ids = ctx.texture((w, h), 2, dtype="i4")
    depth = ctx.depth_texture((w, h))
    fbo = ctx.framebuffer([normal, ids], depth)
    n_buf = np.zeros((h, w, 4), np.float32)
    id_buf = np.zeros((h, w, 2), np.int32)
    d_buf = np.zeros((h, w), np.float32)
    ctx.enable(moderngl.DEPTH_TEST)

    def frame():
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        vao.render(moderngl.TRIANGLES)
        ctx.finish()
        fbo.read_into(n_buf, components=4, attachment=0, dtype="f4")
        fbo.read_into(id_buf, components=2, attachment=1, dtype="i4")
        fbo.read_into(d_buf, attachment=-1, dtype="f4")

    t0 = time.perf_counter()
    frame()
    first = (time.perf_counter() - t0) * 1e3
    for _ in range(WARMUP - 1):   # steady state: buffers allocated, caches filled
        frame()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        frame()
        times.append((time.perf_counter() - t0) * 1e3)
    covered = int(np.count_nonzero(d_buf < 1.0))
    return dict(renderer=ctx.info["GL_RENDERER"], first_ms=first, times_ms=times,
                median_ms=float(np.median(times)), covered=covered,
                threads=os.environ.get("LP_NUM_THREADS", ""),
                glibc_tunables=os.environ.get("GLIBC_TUNABLES", ""))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("--repeats", type=int, default=15)
    a = ap.parse_args()
    print(json.dumps(run(a.scene, a.repeats)))


if __name__ == "__main__":
    main()
