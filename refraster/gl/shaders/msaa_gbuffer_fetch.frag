// Sample u_sample of a multisampled G-buffer (refraster.gl, issue 44): the targets of
// gbuffer.frag / cutaway_gbuffer.frag read with texelFetch into single-sample targets of the
// same layout (0 window depth, 1 eye depth, 2 normal, 3 barycentrics, 4 colour, 5 ids,
// 6 cut flag). The window depth is the depth attachment's own value at the sample.
#version 330 core

uniform sampler2DMS u_depth;     // the multisample depth attachment (DEPTH_COMPONENT32F)
uniform sampler2DMS u_eye;       // R32F
uniform sampler2DMS u_normal;    // RGBA32F
uniform sampler2DMS u_bary;      // RGBA32F
uniform sampler2DMS u_color;     // RGBA32F
uniform isampler2DMS u_ids;      // RGBA32I (primitive id, object id, front facing, covered)
uniform isampler2DMS u_cut;      // R32I (cutaways; any int target otherwise)
uniform int u_sample;

layout(location = 0) out float o_depth;
layout(location = 1) out float o_eye_depth;
layout(location = 2) out vec4 o_normal;
layout(location = 3) out vec4 o_bary;
layout(location = 4) out vec4 o_color;
layout(location = 5) out ivec4 o_ids;
layout(location = 6) out int o_cut;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    o_depth = texelFetch(u_depth, p, u_sample).r;
    o_eye_depth = texelFetch(u_eye, p, u_sample).r;
    o_normal = texelFetch(u_normal, p, u_sample);
    o_bary = texelFetch(u_bary, p, u_sample);
    o_color = texelFetch(u_color, p, u_sample);
    o_ids = texelFetch(u_ids, p, u_sample);
    o_cut = texelFetch(u_cut, p, u_sample).r;
}
