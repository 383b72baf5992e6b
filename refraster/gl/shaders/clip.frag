// 2.5D clip surfaces with caps (refraster.gl; Trapp & Döllner Sec. 3-5, Listing 1, with
// MATH.md §1.1, §1.2, §1.2b and §2.2). One program, two passes into the G-buffer targets of
// gbuffer.frag:
//   solids (u_cap = false): Listing 1 - discard where an enabled surface has g(P) < 0;
//   caps   (u_cap = true):  the displaced grid of surface u_cap_k over solid m, drawn after
//          the solids with GL_LESS: discard where the parity test of solid m's sprite says
//          outside, or another enabled surface clips; shaded from the normal and occlusion
//          maps (or the user's normal, light and diffuse maps).
// Every map is a GL_LINEAR texture with the surface's wrap mode, row 0 at t = 0.
#version 330 core
#ifdef CENTROID_INTERP
#extension GL_ARB_gpu_shader5 : require     // gl_SampleMaskIn
#endif

#define MAX_SURFACES 2

uniform int u_object;
uniform vec3 u_base;
uniform vec4 u_light;            // ambient, diffuse, specular, shininess (the solids' headlight)

// the clip surfaces (world space): O, Û, V̂, N = Û × V̂, (|U|, |V|), (Sx, Sy, Sz)
uniform int u_n_surfaces;
uniform bool u_enabled[MAX_SURFACES];
uniform vec3 u_O[MAX_SURFACES];
uniform vec3 u_Uh[MAX_SURFACES];
uniform vec3 u_Vh[MAX_SURFACES];
uniform vec3 u_N[MAX_SURFACES];
uniform vec2 u_len[MAX_SURFACES];
uniform vec3 u_S[MAX_SURFACES];
uniform sampler2D u_offset0;     // offset map of surface 0 (R32F)
uniform sampler2D u_offset1;     // of surface 1

// the cap pass
uniform bool u_cap;
uniform int u_cap_k;             // the surface this cap belongs to
uniform mat4 u_tmat;             // solid m's sprite_matrix: world → T ∈ [0, 1]³
uniform sampler2DArray u_sprite_depth;   // R32F, layer j in slice j, texelFetch only
uniform isampler2D u_sprite_count;       // R32I
uniform sampler2D u_cap_shading;         // RGBA32F: derived normal (Û, V̂, N frame), occlusion
uniform bool u_has_diffuse, u_has_normal, u_has_lightmap;
uniform sampler2D u_cap_diffuse;         // RGB32F user diffuse
uniform sampler2D u_cap_normal;          // RGB32F user normal, encoded c = 0.5·n + 0.5
uniform sampler2D u_cap_lightmap;        // R32F user light map
uniform vec3 u_cap_color;
uniform mat3 u_view_nmat;                // inverse(view[:3,:3])ᵀ

in vec3 gs_eye;
in vec3 gs_normal;
in vec3 gs_bary;
in vec3 gs_world;
#ifdef SAMPLE_INTERP
// sample rate (GL_SAMPLE_SHADING): the inputs interpolated at the sample here, as the
// multisampled G-buffers do (llvmpipe's own are not the sample's, docs/backends.md)
#include "sample_interp.glsl"
flat in vec3 gs_corner_world[3];
#ifdef CENTROID_INTERP
// pixel rate at a centroid point (raster.interpolation "centroid"): the inputs interpolated
// from the corners at the point llvmpipe's `centroid` picks - the pixel centre where every
// sample is covered, else the first covered sample (gl_SampleMaskIn: this fragment's
// coverage), a point inside both the pixel and the primitive. Not llvmpipe's own `centroid
// noperspective` window position: its noperspective inputs fail on triangles it clips
// (docs/backends.md, "llvmpipe's divide at sample rate").
uniform int u_samples;
uniform vec2 u_sample_xy[16];            // sample s's position in the pixel, GL y up
vec2 centroid_point() {
    int mask = gl_SampleMaskIn[0];
    if (mask == (1 << u_samples) - 1) return gl_FragCoord.xy;
    for (int s = 0; s < u_samples; ++s)
        if (((mask >> s) & 1) != 0) return floor(gl_FragCoord.xy) + u_sample_xy[s];
    return gl_FragCoord.xy;
}
#endif
#endif

layout(location = 0) out float o_depth;
layout(location = 1) out float o_eye_depth;
layout(location = 2) out vec4 o_normal;
layout(location = 3) out vec4 o_bary;
layout(location = 4) out vec4 o_color;
layout(location = 5) out ivec4 o_ids;

// Eq. 2: the surface's texture coordinates of P
vec2 surface_st(int k, vec3 P) {
    vec3 d = P - u_O[k];
    float s = (dot(d, u_Uh[k]) / u_len[k].x) * u_S[k].x;
    float t = (dot(d, u_Vh[k]) / u_len[k].y) * u_S[k].y;
#ifdef FAULT_OFFSET_T_FLIPPED
    t = 1.0 - t;                 // planted fault: the offset map's t axis flipped
#endif
    return vec2(s, t);
}

float offset_at(int k, vec2 st) {
    return k == 0 ? texture(u_offset0, st).r : texture(u_offset1, st).r;
}

// Listing 1 / Eq. 1: g(P) = N·(P − O) + Sz·OM(s, t); the fragment is clipped iff g < 0
bool clipped(int k, vec3 P) {
    if (!u_enabled[k]) return false;
    float g = dot(u_N[k], P - u_O[k]) + u_S[k].z * offset_at(k, surface_st(k, P));
#ifdef FAULT_CLIP_SIGN
    return g > 0.0;              // planted fault: the clip test's sign flipped
#else
    return g < 0.0;
#endif
}

// the volumetric parity test (MATH.md §2.2), as gbuffer.frag's VDS variant: the sprite's
// maps have row 0 at the top and are uploaded flipped, so GL row r covers t ∈ [r/h, (r+1)/h)
bool parity_inside(vec3 T) {
    if (any(lessThan(T, vec3(0.0))) || any(greaterThan(T, vec3(1.0)))) return false;
    ivec2 size = textureSize(u_sprite_count, 0);
    int col = min(int(T.x * float(size.x)), size.x - 1);
    int row = min(int(T.y * float(size.y)), size.y - 1);
    int n = texelFetch(u_sprite_count, ivec2(col, row), 0).r;
    int count = 0;
    for (int j = 0; j < n; ++j) {
        if (texelFetch(u_sprite_depth, ivec3(col, row, j), 0).r <= T.z) ++count;
        else break;
    }
    return (count & 1) == 1;
}

void main() {
    vec3 P = gs_world, eye = gs_eye, nrm = gs_normal, bary = gs_bary;
#ifdef SAMPLE_INTERP
#ifdef CENTROID_INTERP
    sample_interp_at(centroid_point(), eye, nrm, bary);
#else
    sample_interp(eye, nrm, bary);
#endif
#ifndef FAULT_MSAA_DIVIDE_AT_CENTRE
    P = at_sample(bary, gs_corner_world);
#endif
#endif
    for (int k = 0; k < MAX_SURFACES; ++k) {
        if (k >= u_n_surfaces) break;
        if (u_cap && k == u_cap_k) continue;          // a cap is never clipped by its own surface
        if (clipped(k, P)) discard;
    }
    bool front = gl_FrontFacing;
    vec3 n;
    vec3 c;
    if (u_cap) {
#ifndef FAULT_CAP_NO_PARITY
        if (!parity_inside((u_tmat * vec4(P, 1.0)).xyz)) discard;
#endif
        int k = u_cap_k;
        vec2 st = surface_st(k, P);
        vec4 sh = texture(u_cap_shading, st);          // derived normal (Û, V̂, N) and occlusion
        vec3 frame = sh.xyz;
        if (u_has_normal) {
            vec3 e = 2.0 * texture(u_cap_normal, st).xyz - 1.0;
            frame = vec3(e.x, e.y, -e.z);               // z of the encoding points along −N
        }
        float light = u_has_lightmap ? texture(u_cap_lightmap, st).r : sh.w;
        vec3 nw = frame.x * u_Uh[k] + frame.y * u_Vh[k] + frame.z * u_N[k];
        n = u_view_nmat * nw;
        float len = length(n);
        if (len > 0.0) n /= len;
        float el = max(length(eye), 1e-30);
        float shade = light * (0.25 + 0.75 * abs(dot(n, eye)) / el);
        vec3 base = u_has_diffuse ? texture(u_cap_diffuse, st).rgb : u_cap_color;
        c = base * shade;
    } else {
        n = nrm;
        float len = length(n);
        if (len > 0.0) n /= len;
        float el = length(eye);
        float d = el > 0.0 ? min(abs(dot(n, -eye / el)), 1.0) : 1.0;
        c = u_base * (u_light.x + u_light.y * d) + u_light.z * pow(d, u_light.w);
    }
    o_depth = gl_FragCoord.z;
    o_eye_depth = -eye.z;
    o_normal = vec4(n, 0.0);
    o_bary = vec4(bary, 0.0);
    o_color = vec4(clamp(c, 0.0, 1.0), 1.0);
    o_ids = ivec4(gl_PrimitiveID, u_object, front ? 1 : 0, 1);
}
