// 4D halos, pass A of a slice (refraster.gl): the halo depth buffer. Every fragment's Eq. 3
//   d_new = δ + max(0, |2t − 1| − δt) · δd
// (Wang et al. Eq. 3; without halos only surface fragments, |2t − 1| < w_s + a, with d_new = δ)
// into R32F with MIN blending (cleared to a large value), and −1 into the hit target (MIN too).
#version 330 core

uniform float u_delta_t;
uniform float u_delta_d;
uniform float u_ws_aa;      // w_s + a
uniform bool u_halos;

in vec4 gs_attr;
in float gs_b;

layout(location = 0) out vec4 o_min_d;
layout(location = 1) out vec4 o_hit;

void main() {
    float d = gs_attr.x;
    float u = abs(2.0 * gs_attr.y - 1.0);
    float dn = 3.0e38;
#ifdef FAULT_EQ3_HALVED
    float drop = 0.5 * u_delta_d;     // planted fault: Eq. 3's drop-off halved
#else
    float drop = u_delta_d;
#endif
#ifdef FAULT_EQ3_SIGN
    drop = -drop;                     // planted fault: Eq. 3's drop-off subtracted
#endif
    if (u_halos) dn = d + max(0.0, u - u_delta_t) * drop;
    else if (u < u_ws_aa) dn = d;
    o_min_d = vec4(dn, 0.0, 0.0, 0.0);
    o_hit = vec4(-1.0, 0.0, 0.0, 0.0);
}
