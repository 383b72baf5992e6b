// Pass 3 of the edge map (Nienhaus & Döllner Sec. 5.1, refraster.gl): the objects drawn again
// with an NPR style, the edge map projected onto them (looked up at the fragment's own pixel)
// and blended over the style as the paper's fragment shading does (MATH.md §3.1–3.2):
//   inner = (1 − E_N)·shade + E_N·inner_color;  out = (1 − E_Z)·inner + E_Z·profile_color.
// Style: Gooch et al.'s cool-to-warm, t = (1 + n·l)/2, k_cool = cool + α·k_d,
// k_warm = warm + β·k_d, shade = clamp(t·k_warm + (1 − t)·k_cool, 0, 1), n the unit eye-space
// normal. The background keeps the clear colour (the style's background).
#version 330 core

uniform sampler2D u_edge;       // the edge map (NEAREST)
uniform vec3 u_light;           // towards the light, eye space, unit
uniform vec3 u_cool;            // k_cool
uniform vec3 u_warm;            // k_warm
uniform vec3 u_inner_color;
uniform vec3 u_profile_color;

#ifdef FAULT_NOPERSPECTIVE
#define INTERP noperspective
#else
#define INTERP smooth
#endif

INTERP in vec3 gs_eye;
INTERP in vec3 gs_normal;
INTERP in vec3 gs_bary;

out vec4 o_color;

void main() {
    vec3 n = gs_normal;
    float len = length(n);
    if (len > 0.0) n /= len;
    float t = 0.5 * (1.0 + dot(n, u_light));
    vec3 shade = clamp(t * u_warm + (1.0 - t) * u_cool, 0.0, 1.0);
    vec4 e = texelFetch(u_edge, ivec2(gl_FragCoord.xy), 0);
    vec3 inner = (1.0 - e.rgb) * shade + e.rgb * u_inner_color;
    o_color = vec4((1.0 - e.a) * inner + e.a * u_profile_color, 1.0);
}
