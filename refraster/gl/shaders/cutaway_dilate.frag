// Cutaway pass 4 (refraster.gl): D_dil, the minimum of D over each pixel's 3×3 neighbourhood
// (the neighbours inside the image; Sec. 4.2, D-C8), against which back faces are clipped, and
// the cut surfaces' eye-space normals from D_dil (D-C9): P = unproject(x_ndc, y_ndc, D_dil),
// n = normalize(∂P/∂col × ∂P/∂row) by central differences (one-sided at the border), turned
// toward the eye. Targets: 0 R32F D_dil, 1 RGBA32F normal (the normal pass reads D_dil written
// by a previous run of this shader with u_normals).
#version 330 core

uniform sampler2D u_d;         // D (u_normals false) or D_dil (u_normals true), NDC depth
uniform bool u_normals;
uniform mat4 u_inv_proj;
uniform bool u_perspective;

layout(location = 0) out vec4 o_out;

vec3 P(ivec2 q, ivec2 size) {
    vec2 ndc = (vec2(q) + 0.5) * 2.0 / vec2(size) - 1.0;
    vec4 e = u_inv_proj * vec4(ndc, texelFetch(u_d, q, 0).r, 1.0);
    return e.xyz / e.w;
}

void main() {
    ivec2 size = textureSize(u_d, 0);
    ivec2 p = ivec2(gl_FragCoord.xy);
    if (!u_normals) {
        float m = texelFetch(u_d, p, 0).r;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                ivec2 q = clamp(p + ivec2(dx, dy), ivec2(0), size - 1);
                m = min(m, texelFetch(u_d, q, 0).r);
            }
        o_out = vec4(m, 0.0, 0.0, 0.0);
        return;
    }
    if (size.x < 2 || size.y < 2) { o_out = vec4(0.0, 0.0, 1.0, 0.0); return; }
    ivec2 xl = ivec2(max(p.x - 1, 0), p.y), xr = ivec2(min(p.x + 1, size.x - 1), p.y);
    ivec2 yl = ivec2(p.x, max(p.y - 1, 0)), yr = ivec2(p.x, min(p.y + 1, size.y - 1));
    vec3 dcol = (P(xr, size) - P(xl, size)) / float(xr.x - xl.x);
    vec3 drow = (P(yr, size) - P(yl, size)) / float(yr.y - yl.y);
    vec3 n = cross(dcol, drow);
    float len = length(n);
    n = len > 0.0 ? n / len : vec3(0.0, 0.0, 1.0);
    vec3 toward = u_perspective ? -P(p, size) : vec3(0.0, 0.0, 1.0);
    if (dot(n, toward) < 0.0) n = -n;
    o_out = vec4(n, 0.0);
}
