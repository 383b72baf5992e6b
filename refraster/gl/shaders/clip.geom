// Per-triangle attributes of the clip-surface pass (refraster.gl): as gbuffer.geom (flat face
// normal, barycentric corners, gl_PrimitiveID from gl_PrimitiveIDIn), plus the world position.
#version 330 core

layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;

uniform mat3 u_nmat;
uniform bool u_smooth;

in vec3 vs_eye[];
in vec3 vs_obj[];
in vec3 vs_normal[];
in vec3 vs_world[];

out vec3 gs_eye;
out vec3 gs_normal;
out vec3 gs_bary;
out vec3 gs_world;
// the same attributes divided by clip w, and 1/w, interpolated linearly in window space: at
// sample rate clip.frag divides them itself (u_sample_divide; llvmpipe's own perspective
// divide of an input at the sample uses the pixel centre's 1/w, docs/backends.md)
noperspective out vec4 gs_np_world;   // (world / w, 1 / w)
noperspective out vec3 gs_np_eye;
noperspective out vec3 gs_np_normal;
noperspective out vec3 gs_np_bary;

void main() {
    vec3 face = cross(vs_obj[1] - vs_obj[0], vs_obj[2] - vs_obj[0]);
    for (int i = 0; i < 3; ++i) {
        gl_Position = gl_in[i].gl_Position;
        gl_PrimitiveID = gl_PrimitiveIDIn;
        gs_eye = vs_eye[i];
        gs_normal = u_nmat * (u_smooth ? vs_normal[i] : face);
        gs_bary = vec3(i == 0, i == 1, i == 2);
        gs_world = vs_world[i];
        float oow = 1.0 / gl_in[i].gl_Position.w;
        gs_np_world = vec4(gs_world * oow, oow);
        gs_np_eye = gs_eye * oow;
        gs_np_normal = gs_normal * oow;
        gs_np_bary = gs_bary * oow;
        EmitVertex();
    }
    EndPrimitive();
}
