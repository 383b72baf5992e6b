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
#ifdef SAMPLE_INTERP
// at sample rate the corners, interpolated at the sample by clip.frag (sample_interp.glsl)
#include "sample_corners.glsl"
flat out vec3 gs_corner_world[3];
#endif

void main() {
    vec3 face = cross(vs_obj[1] - vs_obj[0], vs_obj[2] - vs_obj[0]);
    for (int i = 0; i < 3; ++i) {
        gl_Position = gl_in[i].gl_Position;
        gl_PrimitiveID = gl_PrimitiveIDIn;
        gs_eye = vs_eye[i];
        gs_normal = u_nmat * (u_smooth ? vs_normal[i] : face);
        gs_bary = vec3(i == 0, i == 1, i == 2);
        gs_world = vs_world[i];
#ifdef SAMPLE_INTERP
        sample_corners(face);
        gs_corner_world = vs_world;
#endif
        EmitVertex();
    }
    EndPrimitive();
}
