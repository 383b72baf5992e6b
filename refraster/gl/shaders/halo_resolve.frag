// 4D halos, pass C of a slice (refraster.gl): the occlusion rule and the back-to-front
// compositing. A hit voxel with a surface fragment of depth δ is SURFACE iff δ ≤ minD + ε
// (MATH.md §5.4), else CARVED; without one, HALO. A surface voxel is composited with
// a = α (coverage 1) or 1 − (1 − α)^c; halo voxels with the halo opacity (0: not drawn).
// Blending (set by the driver): colour SRC_ALPHA, ONE_MINUS_SRC_ALPHA; alpha ONE,
// ONE_MINUS_SRC_ALPHA, so acc ← acc·(1 − a) + a·col and A ← A·(1 − a) + a.
// u_class_pass: instead write the class code (carved 3, surface 2, halo 1) for MAX blending.
#version 330 core

uniform sampler2D u_min_d;
uniform sampler2D u_hit;
uniform sampler2D u_d;
uniform sampler2D u_surf;
uniform float u_eps;
uniform float u_alpha;
uniform float u_halo_alpha;
uniform vec3 u_halo_rgb;
uniform bool u_class_pass;

out vec4 o_color;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    if (texelFetch(u_hit, p, 0).r > -0.5) discard;
    vec2 sd = texelFetch(u_d, p, 0).rg;
    bool has = sd.y > 0.5;
    bool vis = has && sd.x <= texelFetch(u_min_d, p, 0).r + u_eps;
    if (u_class_pass) {
        o_color = vec4(vis ? 2.0 : (has ? 3.0 : 1.0), 0.0, 0.0, 0.0);
        return;
    }
    if (vis) {
        vec4 s = texelFetch(u_surf, p, 0);
        float a = s.a == 1.0 ? u_alpha : 1.0 - pow(1.0 - u_alpha, s.a);
        o_color = vec4(s.rgb, a);
    } else if (u_halo_alpha > 0.0) {
        o_color = vec4(u_halo_rgb, u_halo_alpha);
    } else {
        discard;
    }
}
