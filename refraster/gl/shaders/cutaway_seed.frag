// Cutaway pass 2 (refraster.gl): each rear-hull pixel becomes a seed of the cutaway function
// C_s(x) = z(s) − m(s)·‖x − s‖ (MATH.md §4.1, Eq. 2 as corrected D-C1), in NDC depth and
// view-plane tangent units. The seed's slope from its angle θ (Eq. 3 as corrected, D-C2/D-C4):
//   θ_e = θ · clamp((1 − |x_ndc|)/r, 0, 1) · clamp((1 − |y_ndc|)/r, 0, 1)   (edge compression)
//   m = −P22 · cot θ_e (orthographic), −(P22 + z) · cot θ_e (perspective compensation),
//       P00 · cot θ_e (the paper's basic cone), θ_e clamped below at 1e-3.
// Floor constraint (Sec. 5.5, D-C7; u_floor): the eye-space floor normal n̂, φ = asin(v̂·n̂) with
// v̂ toward the camera, θ_f = clamp(θ_e, 0, max(φ − δ, 0)) + θ_e·smoothstep(0, π/18, −φ), m_f
// from θ_f as m, and the projected floor normal (tangent units, x right, y up), normalized.
// Out: 0 RGBA32F (seed column, seed row with row 0 at the top, z, m); column −1: no seed;
//      1 RGBA32F (m_f, n_x, n_y, 0).
// MSAA (refraster/gl/msaa_techniques.py): the rear hulls are multisampled (u_rear: the
// multisample depth attachment, the depth GL kept at each sample) and this pass reads sample
// u_sample of each pixel: the seeds of that sample's image; with u_depth_resolve 1 (min) or 2
// (max) the depth resolved over the u_samples samples (Vulkan's depth resolve modes; an
// uncovered sample holds the clear value 0), the seeds still sample u_sample's.
#version 330 core
#ifdef MSAA
uniform sampler2DMS u_rear;
uniform isampler2DMS u_hull;
uniform int u_sample;
uniform int u_depth_resolve;
uniform int u_samples;
#define FETCH(t, q) texelFetch(t, q, u_sample)
#define SIZE(t) textureSize(t)
float rear_depth(ivec2 p) {
    float r = FETCH(u_rear, p).r;
    if (u_depth_resolve == 0) return r;
    r = texelFetch(u_rear, p, 0).r;
    for (int i = 1; i < u_samples; ++i) {
        float v = texelFetch(u_rear, p, i).r;
        r = u_depth_resolve == 1 ? min(r, v) : max(r, v);
    }
    return r;
}
#else
uniform sampler2D u_rear;       // R32F window depth of the rear hulls
uniform isampler2D u_hull;      // hull index + 1
#define FETCH(t, q) texelFetch(t, q, 0)
#define SIZE(t) textureSize(t, 0)
float rear_depth(ivec2 p) { return FETCH(u_rear, p).r; }
#endif
uniform float u_theta[8];       // θ per cutaway object (one entry used when u_n_theta == 1)
uniform int u_n_theta;
uniform float u_r;              // edge compression r (0: off)
uniform int u_kind;             // 0 orthographic, 1 perspective compensated, 2 basic cone
uniform vec2 u_p;               // (P22, P00)
uniform bool u_floor;
uniform vec3 u_floor_n;         // eye-space unit floor normal
uniform float u_floor_margin;   // δ
uniform mat4 u_inv_proj;

layout(location = 0) out vec4 o_seed;
layout(location = 1) out vec4 o_floor;

float slope(float theta, float z) {
#ifdef FAULT_SLOPE_FROM_THETA
    // planted fault: the slope from tan θ (the cone's angle taken from the wrong axis)
    float cot = tan(max(theta, 1e-3));
#else
    float cot = 1.0 / tan(max(theta, 1e-3));
#endif
    if (u_kind == 0) return -u_p.x * cot;
    if (u_kind == 1) return -(u_p.x + z) * cot;
    return u_p.y * cot;
}

void main() {
    ivec2 size = SIZE(u_rear);
    ivec2 p = ivec2(gl_FragCoord.xy);
    int hull = FETCH(u_hull, p).r;
    o_floor = vec4(0.0);
    if (hull == 0) { o_seed = vec4(-1.0, -1.0, 0.0, 0.0); return; }
    float z = 2.0 * rear_depth(p) - 1.0;
    vec2 ndc = gl_FragCoord.xy * 2.0 / vec2(size) - 1.0;
    float theta = u_theta[u_n_theta > 1 ? hull - 1 : 0];
    if (u_r > 0.0)
        theta *= clamp((1.0 - abs(ndc.x)) / u_r, 0.0, 1.0) * clamp((1.0 - abs(ndc.y)) / u_r, 0.0, 1.0);
    float m = slope(theta, z);
    if (u_floor) {
        vec4 e = u_inv_proj * vec4(ndc, z, 1.0);
        vec3 pos = e.xyz / e.w;
        vec3 v = u_kind == 0 ? vec3(0.0, 0.0, 1.0) : -normalize(pos);
#ifdef FAULT_FLOOR_FLIPPED
        // planted fault: the floor normal's sign flipped (the camera seems below the floor)
        vec3 n = -u_floor_n;
#else
        vec3 n = u_floor_n;
#endif
        vec2 np = u_kind == 0 ? n.xy : vec2(-pos.z * n.x + pos.x * n.z, -pos.z * n.y + pos.y * n.z);
        // φ = asin(v̂·n̂), as atan(s, √(1 − s²)): llvmpipe's asin is off by ~1e-4 rad here
        float sphi = clamp(dot(v, n), -1.0, 1.0);
        float phi = atan(sphi, sqrt(max(1.0 - sphi * sphi, 0.0)));
        float theta_f = clamp(theta, 0.0, max(phi - u_floor_margin, 0.0))
                      + theta * smoothstep(0.0, 3.14159265358979 / 18.0, -phi);
        float len = length(np);
        o_floor = vec4(slope(theta_f, z), len > 1e-12 ? np / len : vec2(0.0), 0.0);
    }
    o_seed = vec4(float(p.x), float(size.y - 1 - p.y), z, m);
}
