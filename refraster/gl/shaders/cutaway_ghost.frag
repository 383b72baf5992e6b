// Cutaway pass 6 (refraster.gl): ghost lines (Sec. 4.3, MATH.md D-C11). The secondary meshes'
// feature lines (creases, silhouettes, borders; found on the CPU like a GPU team's
// preprocessing) drawn as GL_LINES without depth test into an R32F target blended with MAX:
// a line fragment counts where it lies in the removed region (z < D), is not behind an object
// of interest visible at its pixel, and within g_max (eye units) of D:
//   α = 1 − (d(D) − d(z)) / g_max (fade) or 1, d the eye depth of an NDC depth.
#version 330 core

uniform sampler2D u_D;          // NDC depth
uniform sampler2D u_occluder;   // NDC depth of a visible object of interest, else 2.0
uniform float u_g_max;
uniform bool u_fade;
uniform vec4 u_p;               // P22, P23, P32, P33

out vec4 o_alpha;

float eye_depth(float z) { return -(u_p.y - z * u_p.w) / (z * u_p.z - u_p.x); }

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    float z = 2.0 * gl_FragCoord.z - 1.0;
    float d = texelFetch(u_D, p, 0).r;
    float limit = min(d, texelFetch(u_occluder, p, 0).r);
#ifdef FAULT_GHOST_NOT_DEPTH_TESTED
    limit = texelFetch(u_occluder, p, 0).r;   // planted fault: not tested against D
#endif
    if (!(z < limit)) discard;
    float gap = max(eye_depth(d) - eye_depth(z), 0.0);
    if (!(gap < u_g_max)) discard;
    o_alpha = vec4(u_fade ? clamp(1.0 - gap / u_g_max, 0.0, 1.0) : 1.0, 0.0, 0.0, 0.0);
}
