// Pass 2 of the edge map (Nienhaus & Döllner Sec. 4.1.2, MATH.md §3, refraster.gl): one
// full-screen pass over T_G (texelFetch, clamp-to-edge by clamping the texel coordinate) with
// the discontinuity operators; R = G = B = E_N (inner edges from normals), A = E_Z (profile
// edges from depth), each an edge strength in [0, 1] (0 = no edge; MATH.md §3.2 polarity).
// Neighbourhood as the paper's Fig. 2 (A B C / D X E / F G H); every operator here is
// symmetric under the vertical flip between GL's rows (bottom first) and the image's.
//   normal: 0 diagonal  E_N = 1 − clamp(½(n_A·n_H + n_C·n_F), 0, 1)
//           1 sobel     min(k_n · sqrt(Σ_c G_x² + G_y²) / 8, 1) over the decoded channels
//           2 angle     max over the 8 neighbours of ½(1 − n_X·n_Y)
//   depth:  0 diagonal  1 − (1 − ½|z_A − z_H|)² (1 − ½|z_C − z_F|)²   (as printed)
//           4 diagonal2 the same with second differences z_A + z_H − 2 z_X
//           1 c1 / 2 c1-paper   min(Σ w_i |z_i − z_X| / 12 (or / 8), 1), w = 1 corners, 2 edges
//           3 sobel     min(k_z · sqrt(G_x² + G_y²) / 4, 1)
// E_N is 0 where X is background; strengths below the thresholds become 0; with id edges an
// object-id change in the 8-neighbourhood sets E_Z = 1.
// MSAA (refraster/gl/msaa_techniques.py): T_G and the ids are multisample textures; the pass
// runs at sample rate and reads each neighbour at its own sample, gl_SampleID (the samples'
// edge maps), or at sample 0 with u_sample_zero (the G-buffer resolved by sample_zero); with
// u_average = S > 0 the G-buffer resolved by average: T_G box-filtered over the S samples (an
// uncovered sample counts as the background's encoding, normal 0.5 and depth 1, as
// refraster.edges.gbuffer_of writes it), the ids sample 0's (u_sample_zero).
#version 330 core
#ifdef MSAA
#extension GL_ARB_sample_shading : require
uniform sampler2DMS u_tg;
uniform isampler2DMS u_ids;
uniform bool u_sample_zero;
uniform int u_average;
int g_s;                    // the sample read
#define FETCH(t, q) texelFetch(t, q, g_s)
#define SIZE(t) textureSize(t)
vec4 tg_average(ivec2 q) {
    vec4 acc = vec4(0.0);
    for (int i = 0; i < u_average; ++i)
        acc += texelFetch(u_ids, q, i).r != 0 ? texelFetch(u_tg, q, i) : vec4(0.5, 0.5, 0.5, 1.0);
    return acc / float(u_average);
}
#else
uniform sampler2D u_tg;     // T_G (NEAREST)
uniform isampler2D u_ids;   // object_id + 1, 0 = background
#define FETCH(t, q) texelFetch(t, q, 0)
#define SIZE(t) textureSize(t, 0)
#endif
uniform int u_nmethod;
uniform int u_zmethod;
uniform bool u_use_ids;
uniform float u_k_n;
uniform float u_k_z;
uniform float u_t_inner;
uniform float u_t_profile;

out vec4 o_edge;

ivec2 g_size;
ivec2 g_x;

ivec2 at(int dx, int dy) {
    return clamp(g_x + ivec2(dx, dy), ivec2(0), g_size - 1);
}

bool covered(int dx, int dy) { return FETCH(u_ids, at(dx, dy)).r != 0; }

vec3 nrm(int dx, int dy) {     // decoded normal; 0 on the background
#ifdef MSAA
    if (u_average > 0) return 2.0 * tg_average(at(dx, dy)).rgb - 1.0;
#endif
    if (!covered(dx, dy)) return vec3(0.0);
    return 2.0 * FETCH(u_tg, at(dx, dy)).rgb - 1.0;
}

float dep(int dx, int dy) {    // linear depth; 1 on the background
#ifdef MSAA
    if (u_average > 0) return tg_average(at(dx, dy)).a;
#endif
    if (!covered(dx, dy)) return 1.0;
    return FETCH(u_tg, at(dx, dy)).a;
}

// the paper's letters with row −1 above X: A(−1,−1) B(0,−1) C(1,−1) D(−1,0) E(1,0) F(−1,1)
// G(0,1) H(1,1) (dy = +1 is the next GL row; the operators do not mind which way is up)
float diagonal_normal() {
#ifdef FAULT_ONE_DIAGONAL
    // planted fault: the diagonal operator with one diagonal only (A–H)
    float i_n = dot(nrm(-1, -1), nrm(1, 1));
#else
    float i_n = 0.5 * (dot(nrm(-1, -1), nrm(1, 1)) + dot(nrm(1, -1), nrm(-1, 1)));
#endif
    return 1.0 - clamp(i_n, 0.0, 1.0);
}

float diagonal_depth(bool second) {
    float d_ah, d_cf;
    if (second) {
        float zx2 = 2.0 * dep(0, 0);
        d_ah = (dep(-1, -1) + dep(1, 1)) - zx2;
        d_cf = (dep(1, -1) + dep(-1, 1)) - zx2;
    } else {
        d_ah = dep(-1, -1) - dep(1, 1);
        d_cf = dep(1, -1) - dep(-1, 1);
    }
    float a = 1.0 - 0.5 * abs(d_ah);
    float b = 1.0 - 0.5 * abs(d_cf);
#ifdef FAULT_ONE_DIAGONAL
    b = 1.0;     // planted fault: one diagonal only
#endif
    return 1.0 - (a * a) * (b * b);
}

float c1_depth(float divisor) {
    float zx = dep(0, 0);
    float s = abs(dep(-1, -1) - zx) + 2.0 * abs(dep(0, -1) - zx) + abs(dep(1, -1) - zx)
            + 2.0 * abs(dep(-1, 0) - zx) + 2.0 * abs(dep(1, 0) - zx)
            + abs(dep(-1, 1) - zx) + 2.0 * abs(dep(0, 1) - zx) + abs(dep(1, 1) - zx);
    return min(s / divisor, 1.0);
}

// Sobel of a 3×3 neighbourhood v[row][col] (row 0 = dy −1): (G_y, G_x)
vec2 sobel3(mat3 v) {
    float gy = (v[2][0] + 2.0 * v[2][1] + v[2][2]) - (v[0][0] + 2.0 * v[0][1] + v[0][2]);
    float gx = (v[0][2] + 2.0 * v[1][2] + v[2][2]) - (v[0][0] + 2.0 * v[1][0] + v[2][0]);
#ifdef FAULT_SOBEL_TRANSPOSED
    // planted fault: the G_y kernel written transposed, so it is G_x again (edges along x vanish)
    gy = gx;
#endif
    return vec2(gy, gx);
}

float sobel_depth() {
    mat3 v;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) v[r][c] = dep(c - 1, r - 1);
    vec2 g = sobel3(v);
    return min(u_k_z * sqrt(g.x * g.x + g.y * g.y) / 4.0, 1.0);
}

float sobel_normal() {
    vec3 n[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) n[3 * r + c] = nrm(c - 1, r - 1);
    float s = 0.0;
    for (int k = 0; k < 3; ++k) {
        mat3 v;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) v[r][c] = n[3 * r + c][k];
        vec2 g = sobel3(v);
        s += g.x * g.x + g.y * g.y;
    }
    return min(u_k_n * sqrt(s) / 8.0, 1.0);
}

float angle_normal() {
    vec3 nx = nrm(0, 0);
    float best = 0.0;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            if (dx == 0 && dy == 0) continue;
            best = max(best, 0.5 * (1.0 - dot(nx, nrm(dx, dy))));
        }
    return min(best, 1.0);
}

bool id_edge() {
    int own = FETCH(u_ids, at(0, 0)).r;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
            if (FETCH(u_ids, at(dx, dy)).r != own) return true;
    return false;
}

void main() {
    g_size = SIZE(u_tg);
    g_x = ivec2(gl_FragCoord.xy);
#ifdef MSAA
    g_s = u_sample_zero ? 0 : gl_SampleID;
#ifdef FAULT_MSAA_EDGES_RESOLVED
    g_s = 0;      // planted fault: every sample filters sample 0's G-buffer (the resolved one)
#endif
#endif
    float e_n = 0.0;
    if (covered(0, 0)) {
        if (u_nmethod == 0) e_n = diagonal_normal();
        else if (u_nmethod == 1) e_n = sobel_normal();
        else e_n = angle_normal();
    }
    float e_z;
    if (u_zmethod == 0) e_z = diagonal_depth(false);
    else if (u_zmethod == 4) e_z = diagonal_depth(true);
    else if (u_zmethod == 1) e_z = c1_depth(12.0);
    else if (u_zmethod == 2) e_z = c1_depth(8.0);
    else e_z = sobel_depth();
    if (e_n < u_t_inner) e_n = 0.0;
    if (e_z < u_t_profile) e_z = 0.0;
    if (u_use_ids && id_edge()) e_z = 1.0;
    o_edge = vec4(e_n, e_n, e_n, e_z);
}
