// Adaptive cutaways of refraster.wgpu (Burns & Finkelstein 2008; MATH.md §4, docs/cutaway.md).
// Compiled as one module after gbuffer.wgsl (its Draw, VOut, vs, convention_clip, window_depth,
// unit_normal, headlight_normal, the Ids and Surface records and ids_record, surface_record).
//
//   fs_hull          pass 1: the rear hulls of the objects of interest (depth test greater
//                    against depth32float cleared to 0): r32float window depth, r32sint hull + 1.
//   fs_seed          pass 2, full screen: each rear-hull pixel a seed (column, row, z, m) of
//                    C_s(x) = z − m·‖x − s‖ in OpenGL NDC depth and view-plane tangent units,
//                    and the floor record (m_f, n_x, n_y): two rgba32float (32 bytes).
//   fs_flood         pass 3, one per jump length k: the best of the 9 candidates p + k·{−1,0,1}²
//   fs_flood_final   (the larger C, ties to the smaller row-major index row·W + column); the last
//                    pass writes D = max(C, −1) (−1 where no seed reached) to r32float.
//   fs_dilate        pass 4: D_dil, the 3×3 minimum of D (neighbours inside the image);
//   fs_normals       the cut surfaces' eye-space normals from D_dil by central differences.
//   fs_cut_ids       pass 5, the G-buffer in three passes (as the driver's), each with the
//   fs_cut_surface   cutaway's discard: a secondary fragment is discarded iff z < D (front
//   fs_cut_shade     faces) or z < D_dil (back faces); a kept back-facing secondary fragment is a
//                    cut surface, shaded with the cutaway's normal; fs_cut_ids adds the r32sint
//                    cut flag (28 bytes).
//   vs_line/fs_ghost pass 6: ghost lines, a line list without colour target: the opacity is
//                    written as the fragment's depth into a depth32float attachment cleared to 0
//                    under the depth test greater, so the attachment keeps the maximum over the
//                    lines (MAX blending without float32-blendable).
//
// Rows: WebGPU's framebuffer row 0 is the image's top row, which is the package's row 0 and the
// seeds' row index; NDC y of a pixel centre (column c, row r) is 1 − (r + ½)·2/H.
// Everything is read with textureLoad (no sampler: no float32-filterable).
// Planted faults (tests only; a normal pipeline leaves them false): NDC_Y_FROM_ROW,
// GHOST_NOT_DEPTH_TESTED; the schedule's is host-side (refraster/wgpu/cutaway.py).

override NDC_Y_FROM_ROW: bool = false;          // planted fault: NDC y as GL's gl_FragCoord.y
override GHOST_NOT_DEPTH_TESTED: bool = false;  // planted fault: ghost lines not tested against D

// --- shared ---------------------------------------------------------------------------------
@vertex fn vs_full(@builtin(vertex_index) k: u32) -> @builtin(position) vec4<f32> {
    let x = f32(k & 1u) * 4.0 - 1.0;
    let y = f32(k >> 1u) * 4.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

// NDC (x, y) of the centre of pixel p (column, row; row 0 at the top)
fn pixel_ndc(p: vec2<i32>, size: vec2<i32>) -> vec2<f32> {
    let c = (vec2<f32>(p) + 0.5) * 2.0 / vec2<f32>(size);
    if (NDC_Y_FROM_ROW) {
        return vec2<f32>(c.x - 1.0, c.y - 1.0);
    }
    return vec2<f32>(c.x - 1.0, 1.0 - c.y);
}

// --- pass 1: rear hulls ---------------------------------------------------------------------
struct Hull {
    index: vec4<i32>,          // the cutaway object's index (per-object angles, Sec. 5.3)
};
@group(1) @binding(30) var<uniform> hull_u: Hull;

struct HullOut {
    @location(0) depth: f32,   // r32float window depth
    @location(1) hull: i32,    // r32sint hull index + 1 (0: none)
};
@fragment fn fs_hull(i: VOut) -> HullOut {
    var o: HullOut;
    o.depth = window_depth(i.pos);
    o.hull = hull_u.index.x + 1;
    return o;
}

// --- pass 2: seeds ----------------------------------------------------------------------------
struct Seed {
    theta: array<vec4<f32>, 2>,  // θ per cutaway object (one used when n_theta == 1)
    kind: vec4<i32>,             // n_theta, slope kind (0 ortho, 1 compensated, 2 basic), floor, 0
    p: vec4<f32>,                // P22, P00, edge compression r, floor margin δ
    floor_n: vec4<f32>,          // eye-space unit floor normal
    inv_proj: mat4x4<f32>,
};
@group(0) @binding(31) var<uniform> seed_u: Seed;
@group(0) @binding(32) var rear: texture_2d<f32>;     // r32float window depth of the rear hulls
@group(0) @binding(33) var hulls: texture_2d<i32>;    // r32sint hull index + 1

fn slope(theta: f32, z: f32) -> f32 {
    let cot = 1.0 / tan(max(theta, 1e-3));
    let kind = seed_u.kind.y;
    if (kind == 0) {
        return -seed_u.p.x * cot;
    }
    if (kind == 1) {
        return -(seed_u.p.x + z) * cot;
    }
    return seed_u.p.y * cot;
}

struct SeedOut {
    @location(0) seed: vec4<f32>,    // column, row, z, m; column −1: no seed
    @location(1) floor: vec4<f32>,   // m_f, n_x, n_y, 0
};
@fragment fn fs_seed(@builtin(position) pos: vec4<f32>) -> SeedOut {
    var o: SeedOut;
    let size = vec2<i32>(textureDimensions(rear));
    let p = vec2<i32>(pos.xy);
    let hull = textureLoad(hulls, p, 0).r;
    o.floor = vec4<f32>(0.0);
    if (hull == 0) {
        o.seed = vec4<f32>(-1.0, -1.0, 0.0, 0.0);
        return o;
    }
    let z = 2.0 * textureLoad(rear, p, 0).r - 1.0;
    let ndc = pixel_ndc(p, size);
    var idx = 0;
    if (seed_u.kind.x > 1) {
        idx = hull - 1;
    }
    var theta = seed_u.theta[idx / 4][idx % 4];
    let r = seed_u.p.z;
    if (r > 0.0) {
        theta = theta * clamp((1.0 - abs(ndc.x)) / r, 0.0, 1.0)
                      * clamp((1.0 - abs(ndc.y)) / r, 0.0, 1.0);
    }
    let m = slope(theta, z);
    if (seed_u.kind.z == 1) {
        let e = seed_u.inv_proj * vec4<f32>(ndc, z, 1.0);
        let q = e.xyz / e.w;
        var v = vec3<f32>(0.0, 0.0, 1.0);
        if (seed_u.kind.y != 0) {
            v = -normalize(q);
        }
        let n = seed_u.floor_n.xyz;
        var np = n.xy;
        if (seed_u.kind.y != 0) {
            np = vec2<f32>(-q.z * n.x + q.x * n.z, -q.z * n.y + q.y * n.z);
        }
        // φ = asin(v̂·n̂) written as atan2(s, √(1 − s²))
        let s = clamp(dot(v, n), -1.0, 1.0);
        let phi = atan2(s, sqrt(max(1.0 - s * s, 0.0)));
        let theta_f = clamp(theta, 0.0, max(phi - seed_u.p.w, 0.0))
                    + theta * smoothstep(0.0, 3.14159265358979 / 18.0, -phi);
        let len = length(np);
        var dir = vec2<f32>(0.0);
        if (len > 1e-12) {
            dir = np / len;
        }
        o.floor = vec4<f32>(slope(theta_f, z), dir, 0.0);
    }
    o.seed = vec4<f32>(f32(p.x), f32(p.y), z, m);
    return o;
}

// --- pass 3: jump flooding --------------------------------------------------------------------
struct Flood {
    k: vec4<i32>,                // jump length, floor (0/1), 0, 0
    sampling: vec4<f32>,         // column spacing 2/(W·P00), row spacing 2/(H·P11), 0, 0
};
@group(0) @binding(34) var<uniform> flood_u: Flood;
@group(0) @binding(35) var src_seed: texture_2d<f32>;
@group(0) @binding(36) var src_floor: texture_2d<f32>;

struct Best {
    seed: vec4<f32>,
    floor: vec4<f32>,
    c: f32,
};

fn flood(pos: vec4<f32>) -> Best {
    let size = vec2<i32>(textureDimensions(src_seed));
    let p = vec2<i32>(pos.xy);
    let col = f32(p.x);
    let row = f32(p.y);
    let k = flood_u.k.x;
    var b: Best;
    b.seed = vec4<f32>(-1.0, -1.0, 0.0, 0.0);
    b.floor = vec4<f32>(0.0);
    b.c = 0.0;
    var best_i = 0.0;
    for (var oy = -1; oy <= 1; oy = oy + 1) {
        for (var ox = -1; ox <= 1; ox = ox + 1) {
            let q = p + k * vec2<i32>(ox, oy);
            if (any(q < vec2<i32>(0)) || any(q >= size)) {
                continue;
            }
            let s = textureLoad(src_seed, q, 0);
            if (s.x < 0.0) {
                continue;
            }
            let dx = (col - s.x) * flood_u.sampling.x;
            let dy = (row - s.y) * flood_u.sampling.y;
            let d = sqrt(dy * dy + dx * dx);
            var m = s.w;
            var f = vec4<f32>(0.0);
            if (flood_u.k.y == 1) {
                // directional slope (D-C7): screen direction with y up, rows grow downward
                f = textureLoad(src_floor, q, 0);
                var dd = 1.0;
                if (d != 0.0) {
                    dd = d;
                }
                var a = -(dx * f.y - dy * f.z) / dd;
                if (a > 0.0) {
                    a = min(a, 1.0);
                    m = (1.0 - a) * m + a * f.x;
                }
            }
            var c = s.z;
            if (d != 0.0) {
                c = s.z - m * d;
            }
            let idx = s.y * f32(size.x) + s.x;
            if (b.seed.x < 0.0 || c > b.c || (c == b.c && idx < best_i)) {
                b.seed = s;
                b.floor = f;
                b.c = c;
                best_i = idx;
            }
        }
    }
    return b;
}

@fragment fn fs_flood(@builtin(position) pos: vec4<f32>) -> SeedOut {
    let b = flood(pos);
    var o: SeedOut;
    o.seed = b.seed;
    o.floor = b.floor;
    return o;
}

@fragment fn fs_flood_final(@builtin(position) pos: vec4<f32>) -> @location(0) f32 {
    let b = flood(pos);
    if (b.seed.x < 0.0) {
        return -1.0;
    }
    return max(b.c, -1.0);
}

// --- pass 4: D_dil and the cut normals --------------------------------------------------------
struct Dilate {
    inv_proj: mat4x4<f32>,
    flags: vec4<i32>,            // perspective (0/1), 0, 0, 0
};
@group(0) @binding(37) var<uniform> dil_u: Dilate;
@group(0) @binding(38) var d_in: texture_2d<f32>;     // D (fs_dilate) or D_dil (fs_normals)

@fragment fn fs_dilate(@builtin(position) pos: vec4<f32>) -> @location(0) f32 {
    let size = vec2<i32>(textureDimensions(d_in));
    let p = vec2<i32>(pos.xy);
    var m = textureLoad(d_in, p, 0).r;
    for (var dy = -1; dy <= 1; dy = dy + 1) {
        for (var dx = -1; dx <= 1; dx = dx + 1) {
            let q = clamp(p + vec2<i32>(dx, dy), vec2<i32>(0), size - 1);
            m = min(m, textureLoad(d_in, q, 0).r);
        }
    }
    return m;
}

fn unproject(q: vec2<i32>, size: vec2<i32>) -> vec3<f32> {
    let e = dil_u.inv_proj * vec4<f32>(pixel_ndc(q, size), textureLoad(d_in, q, 0).r, 1.0);
    return e.xyz / e.w;
}

// n = normalize(∂P/∂x × ∂P/∂y) (x right, y up: the row above minus the row below), one-sided
// at the border, turned toward the eye (D-C9)
@fragment fn fs_normals(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(d_in));
    let p = vec2<i32>(pos.xy);
    if (size.x < 2 || size.y < 2) {
        return vec4<f32>(0.0, 0.0, 1.0, 0.0);
    }
    let xl = vec2<i32>(max(p.x - 1, 0), p.y);
    let xr = vec2<i32>(min(p.x + 1, size.x - 1), p.y);
    let yu = vec2<i32>(p.x, max(p.y - 1, 0));             // the row above (y up)
    let yd = vec2<i32>(p.x, min(p.y + 1, size.y - 1));    // the row below
    let dcol = (unproject(xr, size) - unproject(xl, size)) / f32(xr.x - xl.x);
    let drow = (unproject(yu, size) - unproject(yd, size)) / f32(yd.y - yu.y);
    var n = cross(dcol, drow);
    let len = length(n);
    if (len > 0.0) {
        n = n / len;
    } else {
        n = vec3<f32>(0.0, 0.0, 1.0);
    }
    var toward = vec3<f32>(0.0, 0.0, 1.0);
    if (dil_u.flags.x == 1) {
        toward = -unproject(p, size);
    }
    if (dot(n, toward) < 0.0) {
        n = -n;
    }
    return vec4<f32>(n, 0.0);
}

// --- pass 5: the clipped G-buffer -------------------------------------------------------------
struct Cut {
    flags: vec4<i32>,            // secondary (0/1), dilation (0/1), 0, 0
};
@group(1) @binding(40) var<uniform> cut_u: Cut;
@group(1) @binding(41) var cut_d: texture_2d<f32>;       // D, NDC
@group(1) @binding(42) var cut_d_dil: texture_2d<f32>;   // D_dil, NDC
@group(1) @binding(43) var cut_normal: texture_2d<f32>;  // eye-space normal of the cutaway

// the cutaway's fragment test → whether the fragment is a cut surface; discards the removed
fn clip_test(i: VOut, front: bool) -> bool {
    if (cut_u.flags.x == 0) {
        return false;
    }
    let px = vec2<i32>(i.pos.xy);
    let z = 2.0 * window_depth(i.pos) - 1.0;
    var limit = textureLoad(cut_d, px, 0).r;
    if (!front && cut_u.flags.y == 1) {
        limit = textureLoad(cut_d_dil, px, 0).r;
    }
    if (z < limit) {
        discard;
    }
    return !front;
}

fn cut_surface_normal(i: VOut, cut: bool) -> vec3<f32> {
    if (cut) {
        return textureLoad(cut_normal, vec2<i32>(i.pos.xy), 0).xyz;
    }
    return unit_normal(i);
}

struct CutIds {
    @location(0) depth: f32,             // r32float
    @location(1) eye_depth: f32,         // r32float
    @location(2) ids: vec4<i32>,         // rgba32sint: face, object, front facing, covered
    @location(3) cut: i32,               // r32sint
};
@fragment fn fs_cut_ids(i: VOut, @builtin(front_facing) front: bool) -> CutIds {
    let cut = clip_test(i, front);
    let g = ids_record(i, front);
    return CutIds(g.depth, g.eye_depth, g.ids, select(0, 1, cut));
}

@fragment fn fs_cut_surface(i: VOut, @builtin(front_facing) front: bool) -> Surface {
    let cut = clip_test(i, front);
    return surface_record(i, cut_surface_normal(i, cut));
}

@fragment fn fs_cut_shade(i: VOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let cut = clip_test(i, front);
    return headlight_normal(i, cut_surface_normal(i, cut));
}

// --- pass 6: ghost lines (Sec. 4.3, D-C11) ----------------------------------------------------
struct Ghost {
    mvp: mat4x4<f32>,            // projection · view (the segments are in world space)
    p: vec4<f32>,                // P22, P23, P32, P33
    g: vec4<f32>,                // g_max, fade (0/1), 0, 0
};
@group(0) @binding(44) var<uniform> ghost_u: Ghost;
@group(0) @binding(45) var ghost_d: texture_2d<f32>;     // D, NDC
@group(0) @binding(46) var occluder: texture_2d<f32>;    // NDC depth of a visible object of
                                                         // interest, else 2
@vertex fn vs_line(@location(0) pos: vec3<f32>) -> @builtin(position) vec4<f32> {
    return convention_clip(ghost_u.mvp * vec4<f32>(pos, 1.0));
}

fn eye_depth_of(z: f32) -> f32 {
    let p = ghost_u.p;
    return -(p.y - z * p.w) / (z * p.z - p.x);
}

// a line fragment counts where it lies in the removed region (z < D), is not behind an object
// of interest visible at its pixel, and within g_max (eye units) of D:
// α = 1 − (d(D) − d(z)) / g_max (fade) or 1, written as the fragment's depth
@fragment fn fs_ghost(@builtin(position) pos: vec4<f32>) -> @builtin(frag_depth) f32 {
    let p = vec2<i32>(pos.xy);
    let z = 2.0 * pos.z - 1.0;
    let d = textureLoad(ghost_d, p, 0).r;
    var limit = min(d, textureLoad(occluder, p, 0).r);
    if (GHOST_NOT_DEPTH_TESTED) {
        limit = textureLoad(occluder, p, 0).r;
    }
    if (!(z < limit)) {
        discard;
    }
    let gap = max(eye_depth_of(d) - eye_depth_of(z), 0.0);
    if (!(gap < ghost_u.g.x)) {
        discard;
    }
    if (ghost_u.g.y == 1.0) {
        return clamp(1.0 - gap / ghost_u.g.x, 0.0, 1.0);
    }
    return 1.0;
}
