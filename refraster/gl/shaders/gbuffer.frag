// The G-buffer in one pass with multiple render targets (refraster.gl).
// Targets: 0 R32F window depth (gl_FragCoord.z, bit-identical to the 32-bit float depth
// buffer), 1 R32F eye depth, 2 RGBA32F unit normal, 3 RGBA32F barycentrics, 4 RGBA32F colour,
// 5 RGBA32I (primitive id, object id, front facing, covered).
#version 330 core

uniform int u_object;      // the draw call's object_id
uniform vec3 u_base;       // palette[object_id mod len]
uniform vec4 u_light;      // ambient, diffuse, specular, shininess

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

#ifdef FAULT_FILL_RULE_NEITHER
uniform bool u_upper_left;     // glClipControl's origin: gl_FragCoord.y counted from the top
uniform vec2 u_viewport;
flat in vec2 gs_win[3];
#endif

layout(location = 0) out float o_depth;
layout(location = 1) out float o_eye_depth;
layout(location = 2) out vec4 o_normal;
layout(location = 3) out vec4 o_bary;
layout(location = 4) out vec4 o_color;
layout(location = 5) out ivec4 o_ids;

#ifdef VDS
// The volumetric parity test (Trapp & Döllner Sec. 5.3 with MATH.md §2.2): the point T in the
// sprite's texture space [0, 1]³ is inside iff the number of layers at or in front of T.z
// (d_j ≤ T.z, counted front to back, stopping at the first layer behind) at the nearest texel
// is odd; outside the unit cube is outside. u_sprite_depth: layer j in array slice j, GL row r
// covering t ∈ [r/h, (r+1)/h) (the package's maps have row 0 at the top: uploaded flipped);
// u_sprite_count: the number of valid layers per texel.
uniform sampler2DArray u_sprite_depth;   // R32F, read with texelFetch (NEAREST, no filtering)
uniform isampler2D u_sprite_count;       // R32I
INTERP in vec3 gs_T;
layout(location = 6) out int o_inside;

bool parity_inside(vec3 T) {
    if (any(lessThan(T, vec3(0.0))) || any(greaterThan(T, vec3(1.0)))) return false;
    ivec2 size = textureSize(u_sprite_count, 0);
    int col = min(int(T.x * float(size.x)), size.x - 1);
    int row = min(int(T.y * float(size.y)), size.y - 1);
#ifdef FAULT_SPRITE_ROWS_FLIPPED
    row = size.y - 1 - row;          // planted fault: the sprite's rows taken top-down
#endif
    int n = texelFetch(u_sprite_count, ivec2(col, row), 0).r;
    int count = 0;
#ifdef FAULT_PARITY_WRONG_END
    // planted fault: the loop runs back to front but keeps the front-to-back early exit
    for (int j = n - 1; j >= 0; --j) {
#else
    for (int j = 0; j < n; ++j) {
#endif
        if (texelFetch(u_sprite_depth, ivec3(col, row, j), 0).r <= T.z) ++count;
        else break;
    }
    return (count & 1) == 1;
}
#endif

void main() {
    vec3 eye = gs_eye, nrm = gs_normal, bary = gs_bary;
#ifdef SAMPLE_INTERP
    sample_interp(eye, nrm, bary);
#endif
#ifdef FAULT_FILL_RULE_NEITHER
    // planted fault: a pixel centre exactly on an edge (the edge function exactly 0, as it
    // is in float for window coordinates on a half-pixel grid) belongs to neither triangle
    vec2 p = gl_FragCoord.xy;
    if (u_upper_left) p.y = u_viewport.y - p.y;
    p *= 2.0;
    vec2 q0 = gs_win[0], q1 = gs_win[1], q2 = gs_win[2];
    float e0 = (q1.x - q0.x) * (p.y - q0.y) - (q1.y - q0.y) * (p.x - q0.x);
    float e1 = (q2.x - q1.x) * (p.y - q1.y) - (q2.y - q1.y) * (p.x - q1.x);
    float e2 = (q0.x - q2.x) * (p.y - q2.y) - (q0.y - q2.y) * (p.x - q2.x);
    if (e0 == 0.0 || e1 == 0.0 || e2 == 0.0) discard;
#endif
    vec3 n = nrm;
    float len = length(n);
    if (len > 0.0) n /= len;
    // headlight: d = min(|n · (−e/|e|)|, 1), two-sided
    float el = length(eye);
    float d = el > 0.0 ? min(abs(dot(n, -eye / el)), 1.0) : 1.0;
    vec3 c = u_base * (u_light.x + u_light.y * d) + u_light.z * pow(d, u_light.w);
    bool front = gl_FrontFacing;
#ifdef FAULT_FACING_FLIPPED
    // planted fault: the facing read as if the window's rows had been flipped
    front = !front;
#endif
    o_depth = gl_FragCoord.z;
#ifdef FAULT_MSAA_DEPTH_PER_PIXEL
    // planted fault: one depth per fragment (the pixel centre's), tested at every sample
    gl_FragDepth = gl_FragCoord.z;
#endif
#ifdef FAULT_LINEAR_DEPTH_WRITTEN
    o_depth = -eye.z;           // planted fault: the linear eye depth as the window depth
#endif
#ifdef FAULT_SRGB_ENCODED
    // planted fault: the linear colour sRGB-encoded into the float target
    c = clamp(c, 0.0, 1.0);
    c = mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
#endif
    o_eye_depth = -eye.z;
    o_normal = vec4(n, 0.0);
    o_bary = vec4(bary, 0.0);
    o_color = vec4(clamp(c, 0.0, 1.0), 1.0);
    o_ids = ivec4(gl_PrimitiveID, u_object, front ? 1 : 0, 1);
#ifdef VDS
    o_inside = parity_inside(gs_T) ? 1 : 0;
#endif
}
