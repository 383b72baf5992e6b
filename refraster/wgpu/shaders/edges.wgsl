// Edge maps and NPR compositing of refraster.wgpu (Nienhaus & Döllner, WSCG 2003; MATH.md §3).
// Compiled as one module after gbuffer.wgsl (its Draw, VOut, vs and unit_normal).
//
//   fs_tg     pass 1: T_G — the unit eye-space normal encoded 0.5·n + 0.5 in RGB, the linear
//             depth clamp((−z_eye − near)/(far − near), 0, 1) in A — into rgba8unorm (the
//             paper's) or rgba32float, and object_id + 1 into r32sint (0: no fragment).
//   fs_edge   pass 2, a full-screen triangle (vs_full): the discontinuity operators over T_G
//             read with textureLoad (no sampler, so no float32-filterable), the texel
//             coordinate clamped to the image (clamp-to-edge); R = G = B = E_N, A = E_Z.
//   fs_dilate width > 1: a grey dilation with the disk of radius width − 1.
//   fs_npr    pass 3: the objects again with Gooch et al.'s cool-to-warm style and the edge
//             map of the fragment's own pixel blended over it (MATH.md §3.1–3.2).
//
// Rows: WebGPU's framebuffer and textures have row 0 at the top, as the package's images;
// every operator here is symmetric under a vertical flip anyway.
// Planted faults (tests only; a normal pipeline leaves them false): SOBEL_TRANSPOSED,
// ONE_DIAGONAL.

override SOBEL_TRANSPOSED: bool = false;  // planted fault: G_y written as the transposed G_x
override ONE_DIAGONAL: bool = false;      // planted fault: the diagonal operators, A–H only

// --- pass 1: T_G ------------------------------------------------------------------------------
struct NearFar {
    near_far: vec4<f32>,      // near, far (fitted to parameters.bounds), unused, unused
};
@group(1) @binding(10) var<uniform> tg_u: NearFar;

struct Tg {
    @location(0) tg: vec4<f32>,
    @location(1) id: i32,
};
@fragment fn fs_tg(i: VOut) -> Tg {
    var o: Tg;
    let n = unit_normal(i);
    let nf = tg_u.near_far;
    let z = clamp((-i.eye.z - nf.x) / (nf.y - nf.x), 0.0, 1.0);
    o.tg = vec4<f32>(0.5 * n + 0.5, z);
    o.id = u.object_id + 1;
    return o;
}

// --- full-screen passes ---------------------------------------------------------------------
@vertex fn vs_full(@builtin(vertex_index) k: u32) -> @builtin(position) vec4<f32> {
    // one triangle covering the viewport: (−1, −1), (3, −1), (−1, 3)
    let x = f32(k & 1u) * 4.0 - 1.0;
    let y = f32(k >> 1u) * 4.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

struct EdgeParams {
    methods: vec4<i32>,       // normal filter, depth filter, ids (0/1), dilation radius
    gains: vec4<f32>,         // k_n, k_z, inner threshold, profile threshold
};
@group(0) @binding(10) var<uniform> ep: EdgeParams;
@group(0) @binding(11) var t_g: texture_2d<f32>;       // T_G, textureLoad only
@group(0) @binding(12) var t_ids: texture_2d<i32>;     // object_id + 1
@group(0) @binding(13) var t_edge: texture_2d<f32>;    // fs_dilate's input

var<private> g_x: vec2<i32>;
var<private> g_size: vec2<i32>;

fn at(dx: i32, dy: i32) -> vec2<i32> {
    return clamp(g_x + vec2<i32>(dx, dy), vec2<i32>(0), g_size - 1);
}
fn covered(dx: i32, dy: i32) -> bool {
    return textureLoad(t_ids, at(dx, dy), 0).r != 0;
}
fn nrm(dx: i32, dy: i32) -> vec3<f32> {      // decoded normal; 0 on the background
    if (!covered(dx, dy)) {
        return vec3<f32>(0.0);
    }
    return 2.0 * textureLoad(t_g, at(dx, dy), 0).rgb - 1.0;
}
fn dep(dx: i32, dy: i32) -> f32 {            // linear depth; 1 on the background
    if (!covered(dx, dy)) {
        return 1.0;
    }
    return textureLoad(t_g, at(dx, dy), 0).a;
}

// the paper's Fig. 2 letters: A(−1,−1) B(0,−1) C(1,−1) / D(−1,0) X E(1,0) / F(−1,1) G(0,1) H(1,1)
fn diagonal_normal() -> f32 {
    var i_n = 0.5 * (dot(nrm(-1, -1), nrm(1, 1)) + dot(nrm(1, -1), nrm(-1, 1)));
    if (ONE_DIAGONAL) {
        i_n = dot(nrm(-1, -1), nrm(1, 1));
    }
    return 1.0 - clamp(i_n, 0.0, 1.0);
}

fn diagonal_depth(second: bool) -> f32 {
    var d_ah: f32;
    var d_cf: f32;
    if (second) {
        let zx2 = 2.0 * dep(0, 0);
        d_ah = (dep(-1, -1) + dep(1, 1)) - zx2;
        d_cf = (dep(1, -1) + dep(-1, 1)) - zx2;
    } else {
        d_ah = dep(-1, -1) - dep(1, 1);
        d_cf = dep(1, -1) - dep(-1, 1);
    }
    let a = 1.0 - 0.5 * abs(d_ah);
    var b = 1.0 - 0.5 * abs(d_cf);
    if (ONE_DIAGONAL) {
        b = 1.0;
    }
    return 1.0 - (a * a) * (b * b);
}

fn c1_depth(divisor: f32) -> f32 {
    let zx = dep(0, 0);
    let s = abs(dep(-1, -1) - zx) + 2.0 * abs(dep(0, -1) - zx) + abs(dep(1, -1) - zx)
          + 2.0 * abs(dep(-1, 0) - zx) + 2.0 * abs(dep(1, 0) - zx)
          + abs(dep(-1, 1) - zx) + 2.0 * abs(dep(0, 1) - zx) + abs(dep(1, 1) - zx);
    return min(s / divisor, 1.0);
}

// Sobel of a 3 × 3 neighbourhood v[3·row + col] (row 0 = dy −1) → (G_y, G_x)
fn sobel3(v: array<f32, 9>) -> vec2<f32> {
    let gy = (v[6] + 2.0 * v[7] + v[8]) - (v[0] + 2.0 * v[1] + v[2]);
    let gx = (v[2] + 2.0 * v[5] + v[8]) - (v[0] + 2.0 * v[3] + v[6]);
    if (SOBEL_TRANSPOSED) {
        return vec2<f32>(gx, gx);
    }
    return vec2<f32>(gy, gx);
}

fn sobel_depth() -> f32 {
    var v: array<f32, 9>;
    for (var r = 0; r < 3; r = r + 1) {
        for (var c = 0; c < 3; c = c + 1) {
            v[3 * r + c] = dep(c - 1, r - 1);
        }
    }
    let g = sobel3(v);
    return min(ep.gains.y * sqrt(g.x * g.x + g.y * g.y) / 4.0, 1.0);
}

fn sobel_normal() -> f32 {
    var n: array<vec3<f32>, 9>;
    for (var r = 0; r < 3; r = r + 1) {
        for (var c = 0; c < 3; c = c + 1) {
            n[3 * r + c] = nrm(c - 1, r - 1);
        }
    }
    var s = 0.0;
    for (var k = 0; k < 3; k = k + 1) {
        var v: array<f32, 9>;
        for (var j = 0; j < 9; j = j + 1) {
            v[j] = n[j][k];
        }
        let g = sobel3(v);
        s = s + g.x * g.x + g.y * g.y;
    }
    return min(ep.gains.x * sqrt(s) / 8.0, 1.0);
}

fn angle_normal() -> f32 {
    let nx = nrm(0, 0);
    var best = 0.0;
    for (var dy = -1; dy <= 1; dy = dy + 1) {
        for (var dx = -1; dx <= 1; dx = dx + 1) {
            if (dx == 0 && dy == 0) {
                continue;
            }
            best = max(best, 0.5 * (1.0 - dot(nx, nrm(dx, dy))));
        }
    }
    return min(best, 1.0);
}

fn id_edge() -> bool {
    let own = textureLoad(t_ids, at(0, 0), 0).r;
    for (var dy = -1; dy <= 1; dy = dy + 1) {
        for (var dx = -1; dx <= 1; dx = dx + 1) {
            if (textureLoad(t_ids, at(dx, dy), 0).r != own) {
                return true;
            }
        }
    }
    return false;
}

// normal filter: 0 diagonal, 1 sobel, 2 angle; depth filter: 0 diagonal, 1 c1, 2 c1-paper,
// 3 sobel, 4 diagonal2 (refraster/wgpu/edges.py: NORMAL_FILTERS, DEPTH_FILTERS)
@fragment fn fs_edge(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    g_size = vec2<i32>(textureDimensions(t_g));
    g_x = vec2<i32>(pos.xy);
    var e_n = 0.0;
    if (covered(0, 0)) {
        let m = ep.methods.x;
        if (m == 0) {
            e_n = diagonal_normal();
        } else if (m == 1) {
            e_n = sobel_normal();
        } else {
            e_n = angle_normal();
        }
    }
    var e_z: f32;
    let zm = ep.methods.y;
    if (zm == 0) {
        e_z = diagonal_depth(false);
    } else if (zm == 4) {
        e_z = diagonal_depth(true);
    } else if (zm == 1) {
        e_z = c1_depth(12.0);
    } else if (zm == 2) {
        e_z = c1_depth(8.0);
    } else {
        e_z = sobel_depth();
    }
    if (e_n < ep.gains.z) {
        e_n = 0.0;
    }
    if (e_z < ep.gains.w) {
        e_z = 0.0;
    }
    if (ep.methods.z == 1 && id_edge()) {
        e_z = 1.0;
    }
    return vec4<f32>(e_n, e_n, e_n, e_z);
}

// width > 1: the maximum over the disk dx² + dy² ≤ r² (r = width − 1) of the texels inside the
// image (as skimage.morphology.disk)
@fragment fn fs_dilate(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(t_edge));
    let x = vec2<i32>(pos.xy);
    let r = ep.methods.w;
    var best = vec4<f32>(0.0);
    for (var dy = -r; dy <= r; dy = dy + 1) {
        for (var dx = -r; dx <= r; dx = dx + 1) {
            let p = x + vec2<i32>(dx, dy);
            if (dx * dx + dy * dy > r * r || any(p < vec2<i32>(0)) || any(p >= size)) {
                continue;
            }
            best = max(best, textureLoad(t_edge, p, 0));
        }
    }
    return best;
}

// --- pass 3: NPR compositing ------------------------------------------------------------------
struct Npr {
    light: vec4<f32>,         // towards the light, eye space, unit
    cool: vec4<f32>,          // k_cool = cool + α·base
    warm: vec4<f32>,          // k_warm = warm + β·base
    inner_color: vec4<f32>,
    profile_color: vec4<f32>,
};
@group(1) @binding(11) var<uniform> npr: Npr;
@group(1) @binding(12) var npr_edge: texture_2d<f32>;   // the edge map, textureLoad only

@fragment fn fs_npr(i: VOut) -> @location(0) vec4<f32> {
    let n = unit_normal(i);
    let t = 0.5 * (1.0 + dot(n, npr.light.xyz));
    let shade = clamp(t * npr.warm.xyz + (1.0 - t) * npr.cool.xyz, vec3<f32>(0.0),
                      vec3<f32>(1.0));
    let e = textureLoad(npr_edge, vec2<i32>(i.pos.xy), 0);
    let inner = (1.0 - e.rgb) * shade + e.rgb * npr.inner_color.xyz;
    return vec4<f32>((1.0 - e.a) * inner + e.a * npr.profile_color.xyz, 1.0);
}
