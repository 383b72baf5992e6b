// One sample of the multisampled G-buffer (refraster.gl, issue 43): each target read with
// texelFetch at sample u_sample into a single-sample target. The window depth is the depth
// attachment's own value at that sample (the depth test's, evaluated at the sample position),
// not gl_FragCoord.z (one value per fragment, at the pixel centre).
#version 330 core

uniform sampler2DMS u_depth;     // the multisample depth attachment (DEPTH_COMPONENT32F)
uniform sampler2DMS u_bary;      // RGBA32F barycentrics
uniform sampler2DMS u_color;     // RGBA32F colour
uniform isampler2DMS u_ids;      // RGBA32I (primitive id, object id, front facing, covered)
uniform int u_sample;

layout(location = 0) out float o_depth;
layout(location = 1) out vec4 o_bary;
layout(location = 2) out vec4 o_color;
layout(location = 3) out ivec4 o_ids;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    o_depth = texelFetch(u_depth, p, u_sample).r;
    o_bary = texelFetch(u_bary, p, u_sample);
    o_color = texelFetch(u_color, p, u_sample);
    o_ids = texelFetch(u_ids, p, u_sample);
}
