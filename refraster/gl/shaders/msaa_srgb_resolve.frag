// The planted fault msaa_srgb_resolve (refraster.gl, issue 43; test-only): the colour samples
// decoded from sRGB, averaged and encoded again, where the correct resolve (glBlitFramebuffer
// of the float target) averages the stored linear values.
#version 330 core

uniform sampler2DMS u_color;
uniform int u_samples;

layout(location = 0) out vec4 o_color;

vec3 decode(vec3 c) {
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), c));
}

vec3 encode(vec3 c) {
    return mix(12.92 * c, 1.055 * pow(max(c, vec3(0.0031308)), vec3(1.0 / 2.4)) - 0.055,
               step(vec3(0.0031308), c));
}

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec3 sum = vec3(0.0);
    for (int s = 0; s < u_samples; ++s)
        sum += decode(clamp(texelFetch(u_color, p, s).rgb, 0.0, 1.0));
    o_color = vec4(encode(sum / float(u_samples)), 1.0);
}
