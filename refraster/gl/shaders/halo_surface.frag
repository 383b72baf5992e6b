// 4D halos, pass B of a slice (refraster.gl): the voxel's surface fragment — among fragments
// with |2t − 1| < w_s + a, a full-core one (|2t − 1| < w_s) before an anti-aliasing fringe one,
// then the smallest δ — chosen by the depth test LESS on gl_FragDepth = key (full core in
// [0, ½), fringe in [½, 1)); out: δ (R32F) and colour + coverage c = clamp((w_s + a − u)/(2a))
// (RGBA32F).
#version 330 core

uniform float u_ws;
uniform float u_aa;
uniform vec2 u_d_range;     // δ − δ_ref range, for the key

in vec4 gs_attr;
in float gs_b;

layout(location = 0) out vec4 o_d;
layout(location = 1) out vec4 o_surf;

void main() {
    float d = gs_attr.x;
    float u = abs(2.0 * gs_attr.y - 1.0);
    if (!(u < u_ws + u_aa)) discard;
    bool full = u < u_ws;
    float dn = clamp((d - u_d_range.x) / (u_d_range.y - u_d_range.x), 0.0, 1.0);
    gl_FragDepth = (full ? 0.0 : 0.5) + 0.4999 * dn;
    float cov = u_aa <= 0.0 ? 1.0 : min(1.0, max(0.0, (u_ws + u_aa - u) / (2.0 * u_aa)));
    o_d = vec4(d, 1.0, 0.0, 0.0);
    o_surf = vec4(gs_attr.z, gs_attr.w, gs_b, cov);
}
