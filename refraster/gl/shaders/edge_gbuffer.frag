// Pass 1 of the edge map (Nienhaus & Döllner Sec. 4.1.1, refraster.gl): the texture T_G —
// the unit eye-space normal encoded 0.5·n + 0.5 in RGB and the linear depth
// clamp((−z_eye − near) / (far − near), 0, 1) in A — into an RGBA8 (the paper's) or RGBA32F
// target, and object_id + 1 into an R32I target (0: no fragment; the edge pass substitutes the
// background's n = 0, z = 1 there). Vertex and geometry stages: gbuffer.vert, gbuffer.geom.
#version 330 core

uniform int u_object;      // the draw call's object_id
uniform vec2 u_near_far;   // the planes fitted to the enhanced objects (scene parameters)

#ifdef FAULT_NOPERSPECTIVE
#define INTERP noperspective
#else
#define INTERP smooth
#endif

INTERP in vec3 gs_eye;
INTERP in vec3 gs_normal;
INTERP in vec3 gs_bary;
#ifdef SAMPLE_INTERP
#include "sample_interp.glsl"
#endif

layout(location = 0) out vec4 o_tg;
layout(location = 1) out int o_id;

void main() {
    vec3 eye = gs_eye, nrm = gs_normal, bary = gs_bary;
#ifdef SAMPLE_INTERP
    sample_interp(eye, nrm, bary);
#endif
    vec3 n = nrm;
    float len = length(n);
    if (len > 0.0) n /= len;
    float z = clamp((-eye.z - u_near_far.x) / (u_near_far.y - u_near_far.x), 0.0, 1.0);
    o_tg = vec4(0.5 * n + 0.5, z);
    o_id = u_object + 1;
}
