"""A second backend for the golden tests: Mesa llvmpipe through moderngl (headless EGL).

It renders the plain-rendering scenes of a golden directory from their scene packages alone
(``<scene>/package/scene.json`` and its PLY meshes) and writes ``OUT/<scene>/buffers.npz`` the
way any GPU backend would. It imports nothing from refraster, on purpose: it is the outside
opinion the golden compare is tested against.

    python tests/golden_llvmpipe_backend.py GOLDEN_DIR OUT_DIR

Conventions taken from scene.json only: ``clip = projection @ view @ model @ [x y z 1]``
(row-major nested lists, column vectors), CCW front faces, GL window coordinates with row 0 of
the written arrays at the top, depth in a 32-bit float depth buffer (moderngl's own is 24-bit).
"""

from __future__ import annotations

import ctypes
import json
import sys
from pathlib import Path

import numpy as np

VERTEX_SHADER = """
#version 330
uniform mat4 u_mvp;
uniform mat4 u_mv;
uniform mat3 u_nmat;
in vec3 in_pos;
in vec3 in_normal;
in vec3 in_bary;
out vec3 v_eye;
out vec3 v_normal;
out vec3 v_bary;
void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
    v_eye = (u_mv * vec4(in_pos, 1.0)).xyz;
    v_normal = u_nmat * in_normal;
    v_bary = in_bary;
}
"""

FRAGMENT_SHADER = """
#version 330
uniform int u_object;
uniform vec3 u_base;
uniform vec4 u_light;   // ambient, diffuse, specular, shininess
in vec3 v_eye;
in vec3 v_normal;
in vec3 v_bary;
layout(location = 0) out vec4 o_depths;   // window depth, eye depth, front facing
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_bary;
layout(location = 3) out vec4 o_color;
layout(location = 4) out ivec4 o_ids;     // primitive, object, covered
void main() {
    vec3 n = v_normal;
    float len = length(n);
    if (len > 0.0) n /= len;
    float vl = length(v_eye);
    float ndv = vl > 0.0 ? -dot(n, v_eye) / vl : 1.0;
    float d = min(abs(ndv), 1.0);
    vec3 c = u_base * (u_light.x + u_light.y * d) + u_light.z * pow(d, u_light.w);
    o_depths = vec4(gl_FragCoord.z, -v_eye.z, gl_FrontFacing ? 1.0 : 0.0, 1.0);
    o_normal = vec4(n, 0.0);
    o_bary = vec4(v_bary, 0.0);
    o_color = vec4(clamp(c, 0.0, 1.0), 1.0);
    o_ids = ivec4(gl_PrimitiveID, u_object, 1, 0);
}
"""

DEPTH_FUNCS = {"less": "<", "lequal": "<=", "greater": ">", "gequal": ">=", "equal": "==",
               "notequal": "!=", "always": "1", "never": "0"}


def read_ply(path):
    """Binary little-endian PLY as written by the golden export: float x y z [nx ny nz],
    faces as (uchar count, int indices)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise ValueError(f"{path}: only binary little-endian PLY is supported")
    n_vertices = n_faces = 0
    props = []
    element = None
    for line in header:
        words = line.split()
        if words[:1] == ["element"]:
            element = words[1]
            if element == "vertex":
                n_vertices = int(words[2])
            elif element == "face":
                n_faces = int(words[2])
        elif words[:1] == ["property"] and element == "vertex":
            if words[1] != "float":
                raise ValueError(f"{path}: vertex property {words[2]} is {words[1]}, not float")
            props.append(words[2])
    vdata = np.frombuffer(data, "<f4", n_vertices * len(props), end).reshape(n_vertices, -1)
    fdtype = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    faces = np.frombuffer(data, fdtype, n_faces, end + vdata.nbytes)
    if n_faces and not np.all(faces["n"] == 3):
        raise ValueError(f"{path}: only triangles are supported")
    columns = {name: vdata[:, k] for k, name in enumerate(props)}
    vertices = np.stack([columns["x"], columns["y"], columns["z"]], axis=1).astype(np.float64)
    normals = (np.stack([columns["nx"], columns["ny"], columns["nz"]], axis=1).astype(np.float64)
               if "nx" in columns else None)
    return vertices, faces["i"].astype(np.int64), normals


def _float32_depth_texture(ctx, size):
    """A depth texture with 32-bit float storage (GL_DEPTH_COMPONENT32F) via a raw GL call."""
    tex = ctx.depth_texture(size)
    gl = ctypes.CDLL("libGL.so.1")
    gl_texture_2d, gl_depth_component32f, gl_depth_component, gl_float = (
        0x0DE1, 0x8CAC, 0x1902, 0x1406)
    while gl.glGetError():  # errors left by earlier calls are not ours
        pass
    gl.glBindTexture(gl_texture_2d, tex.glo)
    gl.glTexImage2D(gl_texture_2d, 0, gl_depth_component32f, size[0], size[1], 0,
                    gl_depth_component, gl_float, None)
    error = gl.glGetError()
    if error:
        raise RuntimeError(f"glTexImage2D(GL_DEPTH_COMPONENT32F) failed: GL error {error:#x}")
    return tex


def render_scene(ctx, package_dir):
    scene = json.loads((package_dir / "scene.json").read_text())
    if scene["schema"] != "refraster.scene" or scene["schema_version"] > 1:
        raise ValueError(f"{package_dir}: unsupported scene schema")
    width, height = scene["viewport"]["width"], scene["viewport"]["height"]
    raster, shading = scene["raster"], scene["shading"]
    view = np.array(scene["camera"]["view"], np.float64)
    proj = np.array(scene["camera"]["projection"], np.float64)

    prog = ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=FRAGMENT_SHADER)
    targets = [ctx.texture((width, height), 4, dtype="f4") for _ in range(4)]
    targets.append(ctx.texture((width, height), 4, dtype="i4"))
    depth = _float32_depth_texture(ctx, (width, height))
    fbo = ctx.framebuffer(color_attachments=targets, depth_attachment=depth)
    fbo.use()
    ctx.viewport = (0, 0, width, height)
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=raster["clear_depth"])
    ctx.enable(ctx.DEPTH_TEST)
    ctx.depth_func = DEPTH_FUNCS[raster["depth_func"]]
    if raster["cull"] == "none":
        ctx.disable(ctx.CULL_FACE)
    else:
        ctx.enable(ctx.CULL_FACE)
        ctx.cull_face = raster["cull"]
    ctx.front_face = "ccw"
    prog["u_light"].value = (shading["ambient"], shading["diffuse"], shading["specular"],
                             shading["shininess"])
    palette = shading["palette"]
    for draw in scene["draws"]:
        vertices, faces, vnormals = read_ply(package_dir / draw["mesh"])
        model = np.array(draw["model"], np.float64)
        mv = view @ model
        nmat = np.linalg.inv(mv[:3, :3]).T
        corners = vertices[faces]                                   # (F, 3, 3)
        if raster["normals"] == "smooth":
            normals = vnormals[faces]
        else:
            face_n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            normals = np.repeat(face_n[:, None, :], 3, axis=1)
        bary = np.broadcast_to(np.eye(3), corners.shape)
        data = np.concatenate([corners, normals, bary], axis=2).astype("f4")
        vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 3f 3f", "in_pos", "in_normal", "in_bary")])
        # GL uniforms are column-major: pass the transpose's bytes
        prog["u_mvp"].write((proj @ mv).T.astype("f4").tobytes())
        prog["u_mv"].write(mv.T.astype("f4").tobytes())
        prog["u_nmat"].write(nmat.T.astype("f4").tobytes())
        prog["u_object"].value = draw["object_id"]
        prog["u_base"].value = tuple(palette[draw["object_id"] % len(palette)])
        vao.render()
        vao.release()
        vbo.release()

    def read(tex, dtype):
        a = np.frombuffer(tex.read(), dtype).reshape(height, width, 4)
        return a[::-1].copy()                                      # GL row 0 is the bottom

    depths, normal, bary, color = (read(t, "<f4") for t in targets[:4])
    ids = read(targets[4], "<i4")
    for obj in (fbo, depth, prog, *targets):
        obj.release()
    covered = ids[..., 2] == 1
    bg = np.array(shading["background"], np.float32)
    return {
        "depth": np.where(covered, depths[..., 0], np.float32(raster["clear_depth"])),
        "eye_depth": np.where(covered, depths[..., 1], np.float32(np.inf)),
        "normal": np.where(covered[..., None], normal[..., :3], 0).astype(np.float32),
        "prim_id": np.where(covered, ids[..., 0], -1).astype(np.int32),
        "object_id": np.where(covered, ids[..., 1], -1).astype(np.int32),
        "front_facing": covered & (depths[..., 2] > 0.5),
        "barycentric": np.where(covered[..., None], bary[..., :3], 0).astype(np.float32),
        "color": np.where(covered[..., None], color[..., :3], bg).astype(np.float32),
    }


def main(golden_dir, out_dir):
    import moderngl
    ctx = moderngl.create_standalone_context(backend="egl")
    rendered = []
    for scene_json in sorted(Path(golden_dir).glob("*/package/scene.json")):
        if json.loads(scene_json.read_text())["technique"] != "render":
            continue
        name = scene_json.parent.parent.name
        buffers = render_scene(ctx, scene_json.parent)
        (Path(out_dir) / name).mkdir(parents=True, exist_ok=True)
        np.savez_compressed(Path(out_dir) / name / "buffers.npz", **buffers)
        rendered.append(name)
    leaked = sorted(m for m in sys.modules if m == "refraster" or m.startswith("refraster."))
    print(json.dumps({"renderer": ctx.info["GL_RENDERER"], "scenes": rendered,
                      "refraster_modules": leaked}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
