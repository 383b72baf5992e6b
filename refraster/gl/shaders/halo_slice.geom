// 4D halos, slicing (Wang et al. Sec. 4.5, MATH.md §5.6; refraster.gl): each tetrahedron comes
// in as one lines_adjacency primitive (its 4 vertices) and is cut by the plane z = u_c: with
// s_i = z_i − c and "positive" meaning s ≥ 0, one positive (or one negative) vertex gives a
// triangle on its three edges, two give the quad [e_ac, e_ad, e_bd, e_bc] as the triangles
// (e_ac, e_ad, e_bd), (e_ac, e_bd, e_bc); each corner interpolated from the endpoint with the
// smaller global index, λ = s_i / (s_i − s_j), so shared edges agree.
#version 330 core

layout(lines_adjacency) in;
layout(triangle_strip, max_vertices = 6) out;

uniform float u_c;

in vec2 vs_xy[];
in float vs_z[];
in vec4 vs_attr[];
in float vs_b[];
flat in int vs_id[];

out vec4 gs_attr;
out float gs_b;

void corner(int i, int j) {
    if (vs_id[i] > vs_id[j]) { int k = i; i = j; j = k; }
    float si = vs_z[i] - u_c, sj = vs_z[j] - u_c;
    float lam = si / (si - sj);
    gl_Position = vec4(vs_xy[i] + lam * (vs_xy[j] - vs_xy[i]), 0.0, 1.0);
    gs_attr = vs_attr[i] + lam * (vs_attr[j] - vs_attr[i]);
    gs_b = vs_b[i] + lam * (vs_b[j] - vs_b[i]);
    EmitVertex();
}

void main() {
    bool p[4];
    int npos = 0;
    for (int i = 0; i < 4; ++i) { p[i] = vs_z[i] - u_c >= 0.0; npos += p[i] ? 1 : 0; }
    if (npos == 0 || npos == 4) return;
    if (npos == 2) {
        int a = -1, b = -1, c = -1, d = -1;
        for (int i = 0; i < 4; ++i) {
            if (p[i]) { if (a < 0) a = i; else b = i; }
            else if (c < 0) c = i; else d = i;
        }
        corner(a, c); corner(a, d); corner(b, d); EndPrimitive();
        corner(a, c); corner(b, d); corner(b, c); EndPrimitive();
        return;
    }
    int lone = 0;
    for (int i = 0; i < 4; ++i) if (p[i] == (npos == 1)) lone = i;
    corner(lone, (lone + 1) % 4); corner(lone, (lone + 2) % 4); corner(lone, (lone + 3) % 4);
    EndPrimitive();
}
