// A multisampled image pass's output (refraster.gl, issue 44): sample u_sample of each pixel,
// or with u_sample = -1 the box filter of the samples, Σ_i texelFetch(u_src, p, i) / S in
// float (the resolve of the samples' edge maps into a float target; glBlitFramebuffer would
// resolve an RGBA8 map into RGBA8 and round the mean).
#version 330 core

uniform sampler2DMS u_src;
uniform int u_samples;
uniform int u_sample;

out vec4 o_out;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    if (u_sample >= 0) { o_out = texelFetch(u_src, p, u_sample); return; }
    vec4 sum = vec4(0.0);
    for (int i = 0; i < u_samples; ++i) sum += texelFetch(u_src, p, i);
    o_out = sum / float(u_samples);
}
