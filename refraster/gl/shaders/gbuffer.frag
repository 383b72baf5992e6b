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

layout(location = 0) out float o_depth;
layout(location = 1) out float o_eye_depth;
layout(location = 2) out vec4 o_normal;
layout(location = 3) out vec4 o_bary;
layout(location = 4) out vec4 o_color;
layout(location = 5) out ivec4 o_ids;

void main() {
    vec3 n = gs_normal;
    float len = length(n);
    if (len > 0.0) n /= len;
    // headlight: d = min(|n · (−e/|e|)|, 1), two-sided
    float el = length(gs_eye);
    float d = el > 0.0 ? min(abs(dot(n, -gs_eye / el)), 1.0) : 1.0;
    vec3 c = u_base * (u_light.x + u_light.y * d) + u_light.z * pow(d, u_light.w);
    bool front = gl_FrontFacing;
#ifdef FAULT_FACING_FLIPPED
    // planted fault: the facing read as if the window's rows had been flipped
    front = !front;
#endif
    o_depth = gl_FragCoord.z;
    o_eye_depth = -gs_eye.z;
    o_normal = vec4(n, 0.0);
    o_bary = vec4(gs_bary, 0.0);
    o_color = vec4(clamp(c, 0.0, 1.0), 1.0);
    o_ids = ivec4(gl_PrimitiveID, u_object, front ? 1 : 0, 1);
}
