// Cutaway pass 5 (Burns & Finkelstein Sec. 4.1–4.2, refraster.gl): the G-buffer of
// gbuffer.frag with the clipping fragment test — a secondary fragment is discarded iff
// z < D (front faces) or z < D_dil (back faces), NDC depth at its pixel; fragments of the
// objects of interest are always kept — and the cut surfaces: a back-facing secondary fragment
// takes the normal of the cutaway surface (D-C9) and is shaded with it. Target 6: R32I cut flag.
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

layout(location = 0) out float o_depth;
layout(location = 1) out float o_eye_depth;
layout(location = 2) out vec4 o_normal;
layout(location = 3) out vec4 o_bary;
layout(location = 4) out vec4 o_color;
layout(location = 5) out ivec4 o_ids;
layout(location = 6) out int o_cut;

uniform bool u_secondary;
uniform bool u_dilation;
uniform sampler2D u_D;         // R32F NDC depth
uniform sampler2D u_D_dil;     // R32F NDC depth, 3×3 minimum of D
uniform sampler2D u_cut_normal; // RGBA32F eye-space normal of the cutaway surface


void main() {
    vec3 eye = gs_eye, nrm = gs_normal, bary = gs_bary;
#ifdef SAMPLE_INTERP
    sample_interp(eye, nrm, bary);
#endif
    ivec2 px = ivec2(gl_FragCoord.xy);
    bool cut = false;
    if (u_secondary) {
        float z = 2.0 * gl_FragCoord.z - 1.0;
        float limit = (gl_FrontFacing || !u_dilation) ? texelFetch(u_D, px, 0).r
                                                      : texelFetch(u_D_dil, px, 0).r;
        if (z < limit) discard;
        cut = !gl_FrontFacing;
    }
    vec3 n = nrm;
    float len = length(n);
    if (len > 0.0) n /= len;
    if (cut) n = texelFetch(u_cut_normal, px, 0).xyz;
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
    o_eye_depth = -eye.z;
    o_normal = vec4(n, 0.0);
    o_bary = vec4(bary, 0.0);
    o_color = vec4(clamp(c, 0.0, 1.0), 1.0);
    o_ids = ivec4(gl_PrimitiveID, u_object, front ? 1 : 0, 1);
    o_cut = cut ? 1 : 0;
}
