// Cutaway pass 2 (refraster.gl): each rear-hull pixel becomes a seed of the cutaway function
// C_s(x) = z(s) − m(s)·‖x − s‖ (MATH.md §4.1, Eq. 2 as corrected D-C1), in NDC depth and
// view-plane tangent units. The seed's slope from its angle θ (Eq. 3 as corrected, D-C2/D-C4):
//   θ_e = θ · clamp((1 − |x_ndc|)/r, 0, 1) · clamp((1 − |y_ndc|)/r, 0, 1)   (edge compression)
//   m = −P22 · cot θ_e (orthographic), −(P22 + z) · cot θ_e (perspective compensation),
//       P00 · cot θ_e (the paper's basic cone), θ_e clamped below at 1e-3.
// Out: RGBA32F (seed column, seed row with row 0 at the top, z, m); column −1: no seed.
#version 330 core

uniform sampler2D u_rear;       // R32F window depth of the rear hulls
uniform isampler2D u_hull;      // hull index + 1
uniform float u_theta[8];       // θ per cutaway object (one entry used when u_n_theta == 1)
uniform int u_n_theta;
uniform float u_r;              // edge compression r (0: off)
uniform int u_kind;             // 0 orthographic, 1 perspective compensated, 2 basic cone
uniform vec2 u_p;               // (P22, P00)

out vec4 o_seed;

void main() {
    ivec2 size = textureSize(u_rear, 0);
    ivec2 p = ivec2(gl_FragCoord.xy);
    int hull = texelFetch(u_hull, p, 0).r;
    if (hull == 0) { o_seed = vec4(-1.0, -1.0, 0.0, 0.0); return; }
    float z = 2.0 * texelFetch(u_rear, p, 0).r - 1.0;
    vec2 ndc = gl_FragCoord.xy * 2.0 / vec2(size) - 1.0;
    float theta = u_theta[u_n_theta > 1 ? hull - 1 : 0];
    if (u_r > 0.0)
        theta *= clamp((1.0 - abs(ndc.x)) / u_r, 0.0, 1.0) * clamp((1.0 - abs(ndc.y)) / u_r, 0.0, 1.0);
#ifdef FAULT_SLOPE_FROM_THETA
    // planted fault: the slope from tan θ (the cone's angle taken from the wrong axis)
    float cot = tan(max(theta, 1e-3));
#else
    float cot = 1.0 / tan(max(theta, 1e-3));
#endif
    float m;
    if (u_kind == 0) m = -u_p.x * cot;
    else if (u_kind == 1) m = -(u_p.x + z) * cot;
    else m = u_p.y * cot;
    o_seed = vec4(float(p.x), float(size.y - 1 - p.y), z, m);
}
