// Per-triangle attributes of the G-buffer (refraster.gl): the flat normal
// (v1 − v0) × (v2 − v0) of the object-space triangle, the barycentric corners (1,0,0),
// (0,1,0), (0,0,1), and gl_PrimitiveID passed through (the face index within its draw call).
#version 330 core

layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;

uniform mat3 u_nmat;       // normal matrix inverse(view·model)[:3,:3]ᵀ
uniform bool u_smooth;     // true: the PLY's vertex normals; false: the face normal

in vec3 vs_eye[];
in vec3 vs_obj[];
in vec3 vs_normal[];

#ifdef FAULT_NOPERSPECTIVE
#define INTERP noperspective
#else
#define INTERP smooth
#endif

INTERP out vec3 gs_eye;
INTERP out vec3 gs_normal;
INTERP out vec3 gs_bary;
#ifdef FAULT_FILL_RULE_NEITHER
uniform vec2 u_viewport;
flat out vec2 gs_win[3];   // the window positions (×2, pixel centres on odd integers)
#endif
#ifdef SAMPLE_INTERP
uniform vec2 u_viewport_px;            // width, height: the window transform of the corners
flat out vec3 gs_corner_win[3];
flat out vec3 gs_corner_eye[3];
flat out vec3 gs_corner_normal[3];
#endif
#ifdef VDS
in vec3 vs_T[];
INTERP out vec3 gs_T;
#endif

void main() {
    vec3 face = cross(vs_obj[1] - vs_obj[0], vs_obj[2] - vs_obj[0]);
#ifdef FAULT_FILL_RULE_NEITHER
    vec2 win[3];
    for (int i = 0; i < 3; ++i) {
        vec4 c = gl_in[i].gl_Position;
        win[i] = c.w > 0.0 ? (c.xy / c.w * 0.5 + 0.5) * u_viewport * 2.0 : vec2(-1e9);
    }
#endif
#ifdef SAMPLE_INTERP
    vec3 cw[3], ce[3], cn[3];
    for (int i = 0; i < 3; ++i) {
        vec4 c = gl_in[i].gl_Position;
        cw[i] = vec3((c.xy / c.w * 0.5 + 0.5) * u_viewport_px, 1.0 / c.w);
        ce[i] = vs_eye[i];
        cn[i] = u_nmat * (u_smooth ? vs_normal[i] : face);
    }
#endif
    for (int i = 0; i < 3; ++i) {
        gl_Position = gl_in[i].gl_Position;
#ifdef SAMPLE_INTERP
        gs_corner_win = cw;
        gs_corner_eye = ce;
        gs_corner_normal = cn;
#endif
        gl_PrimitiveID = gl_PrimitiveIDIn;
        gs_eye = vs_eye[i];
        gs_normal = u_nmat * (u_smooth ? vs_normal[i] : face);
        gs_bary = vec3(i == 0, i == 1, i == 2);
#ifdef FAULT_FILL_RULE_NEITHER
        gs_win = win;
#endif
#ifdef VDS
        gs_T = vs_T[i];
#endif
        EmitVertex();
    }
    EndPrimitive();
}
