// Cutaway pass 3 (refraster.gl): one jump-flooding pass with step k (Rong & Tan; Burns &
// Finkelstein Sec. 4.2), ping-pong between two RGBA32F textures of seed records (column, row
// with row 0 at the top, z, m): each pixel keeps the best of the seeds its 9 candidates
// p + k·{−1, 0, 1}² hold, the best being the larger C_s(x) = z − m·‖x − s‖ (distances in
// view-plane tangent units: u_sampling = (column spacing, row spacing)), ties to the smaller
// row-major index row·W + column (refraster.cutaway.flood's rule). u_final: write
// D = max(C, −1) (NDC depth; −1 where no seed reached) to a R32F target instead.
#version 330 core

uniform sampler2D u_src;
uniform sampler2D u_src_floor;  // (m_f, n_x, n_y) of each record's seed (u_floor)
uniform bool u_floor;
uniform int u_k;
uniform vec2 u_sampling;
uniform bool u_final;

layout(location = 0) out vec4 o_out;
layout(location = 1) out vec4 o_floor;

void main() {
    ivec2 size = textureSize(u_src, 0);
    ivec2 p = ivec2(gl_FragCoord.xy);
    float row = float(size.y - 1 - p.y), col = float(p.x);
    vec4 best = vec4(-1.0, -1.0, 0.0, 0.0);
    vec4 best_f = vec4(0.0);
    float best_c = 0.0, best_i = 0.0;
    for (int oy = -1; oy <= 1; ++oy)
        for (int ox = -1; ox <= 1; ++ox) {
            ivec2 q = p + u_k * ivec2(ox, oy);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            vec4 s = texelFetch(u_src, q, 0);
            if (s.x < 0.0) continue;
            float dx = (col - s.x) * u_sampling.x;
            float dy = (row - s.y) * u_sampling.y;
            float d = sqrt(dy * dy + dx * dx);
            float m = s.w;
            vec4 f = vec4(0.0);
            if (u_floor) {
                // directional slope (D-C7): screen direction with y up, rows grow downward
                f = texelFetch(u_src_floor, q, 0);
                float a = -(dx * f.y - dy * f.z) / (d != 0.0 ? d : 1.0);
                if (a > 0.0) { a = min(a, 1.0); m = (1.0 - a) * m + a * f.x; }
            }
            float c = d == 0.0 ? s.z : s.z - m * d;
            float idx = s.y * float(size.x) + s.x;
            if (best.x < 0.0 || c > best_c || (c == best_c && idx < best_i)) {
                best = s; best_f = f; best_c = c; best_i = idx;
            }
        }
    if (u_final) o_out = vec4(best.x < 0.0 ? -1.0 : max(best_c, -1.0), 0.0, 0.0, 0.0);
    else o_out = best;
    o_floor = best_f;
}
