// 4D halos (Wang et al. 2013) in WGSL for refraster.wgpu (refraster/wgpu/halos.py). A module of
// its own (not compiled after gbuffer.wgsl). Core WebGPU has no geometry shader: per slicing
// plane z = c_k, back (smallest z) to front,
//   S. cs_slice (compute): every tetrahedron cut by the plane into 0, 1 or 2 triangles, written
//      to fixed slots (2 triangles = 6 vertices per tetrahedron; an unused slot is a
//      degenerate triangle at the origin, which covers no pixel) of a storage buffer that the
//      next passes draw as their vertex buffer;
//   A. fs_halo_depth: Eq. 3's halo depth; the per-pixel MINIMUM kept by a depth32float
//      attachment under `less` (the value mapped into [0, ½] as the fragment depth; a fragment
//      without one, 0.75) — float32 is not blendable in core WebGPU — and the hit flag;
//   B. fs_surface: the voxel's surface fragment by the depth test `less` on a (core, δ) key;
//   C. fs_resolve (full screen): the occlusion rule and the back-to-front compositing into a
//      ping-pong pair of rgba32float (colour, opacity) + r32sint (class, its maximum) targets,
//      the previous pair read with textureLoad: no blending.

struct Params {
    lo: f32,            // the halo-depth key's range [lo, hi] (δ − δ_ref units)
    hi: f32,
    delta_t: f32,
    delta_d: f32,
    ws: f32,            // w_s
    aa: f32,            // a, the anti-aliasing ramp
    d_lo: f32,          // the surface key's δ range
    d_hi: f32,
    eps_key: f32,       // ε of the occlusion rule in key units: ½·ε/(hi − lo)
    alpha: f32,
    halo_alpha: f32,
    halos: u32,
    halo_rgb: vec3<f32>,
    dz: f32,            // the slab thickness
};

struct Slice {
    c: f32,             // the plane's z (relative to the first plane)
    n_tets: u32,
};

// planted faults (tests only; refraster.wgpu.TECHNIQUE_FAULTS)
override PLANE_HALF_SLAB: bool = false;   // the plane at c + ½·dz: a slab boundary

@group(0) @binding(0) var<uniform> prm: Params;

@group(1) @binding(1) var<uniform> sl: Slice;
@group(1) @binding(2) var<storage, read> verts: array<f32>;      // 8 per vertex
@group(1) @binding(3) var<storage, read> tets: array<vec4<i32>>;
@group(1) @binding(4) var<storage, read_write> tris: array<vec4<f32>>;   // 2 per corner

// --- S: slicing --------------------------------------------------------------------------------

// corner of edge (i, j) of the tetrahedron (global ids g, plane distances s), interpolated from
// the endpoint with the smaller global index, λ = s_i / (s_i − s_j): shared edges agree
fn corner(slot: u32, g: array<i32, 4>, s: array<f32, 4>, i0: i32, j0: i32) {
    var i = i0;
    var j = j0;
    if (g[i] > g[j]) {
        i = j0;
        j = i0;
    }
    let lam = s[i] / (s[i] - s[j]);
    let a = 8 * g[i];
    let b = 8 * g[j];
    var v: array<f32, 8>;
    for (var k = 0; k < 8; k += 1) {
        let vi = verts[a + k];
        v[k] = vi + lam * (verts[b + k] - vi);
    }
    // (x, y, δ, t), (r, g, b, 0); v[2] is z
    tris[2u * slot] = vec4<f32>(v[0], v[1], v[3], v[4]);
    tris[2u * slot + 1u] = vec4<f32>(v[5], v[6], v[7], 0.0);
}

@compute @workgroup_size(64)
fn cs_slice(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if (k >= sl.n_tets) {
        return;
    }
    var c = sl.c;
    if (PLANE_HALF_SLAB) {
        c = c + 0.5 * prm.dz;           // planted fault
    }
    let t = tets[k];
    let g = array<i32, 4>(t.x, t.y, t.z, t.w);
    var s: array<f32, 4>;
    var p: array<bool, 4>;
    var npos = 0;
    for (var i = 0; i < 4; i += 1) {
        s[i] = verts[8 * g[i] + 2] - c;
        p[i] = s[i] >= 0.0;
        npos += select(0, 1, p[i]);
    }
    let base = 6u * k;
    for (var q = 0u; q < 12u; q += 1u) {
        tris[2u * base + q] = vec4<f32>(0.0);
    }
    if (npos == 0 || npos == 4) {
        return;
    }
    if (npos == 2) {
        var a = -1;
        var b = -1;
        var cc = -1;
        var d = -1;
        for (var i = 0; i < 4; i += 1) {
            if (p[i]) {
                if (a < 0) { a = i; } else { b = i; }
            } else {
                if (cc < 0) { cc = i; } else { d = i; }
            }
        }
        // the quad [e_ac, e_ad, e_bd, e_bc] as (e_ac, e_ad, e_bd), (e_ac, e_bd, e_bc)
        corner(base, g, s, a, cc);
        corner(base + 1u, g, s, a, d);
        corner(base + 2u, g, s, b, d);
        corner(base + 3u, g, s, a, cc);
        corner(base + 4u, g, s, b, d);
        corner(base + 5u, g, s, b, cc);
        return;
    }
    var lone = 0;
    for (var i = 0; i < 4; i += 1) {
        if (p[i] == (npos == 1)) { lone = i; }
    }
    corner(base, g, s, lone, (lone + 1) % 4);
    corner(base + 1u, g, s, lone, (lone + 2) % 4);
    corner(base + 2u, g, s, lone, (lone + 3) % 4);
}

// --- A, B: the slice's triangles --------------------------------------------------------------

struct SOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) attr: vec4<f32>,       // δ − δ_ref, t, r, g
    @location(1) b: f32,
};

@vertex fn vs_slice(@location(0) p0: vec4<f32>, @location(1) p1: vec4<f32>) -> SOut {
    var o: SOut;
    o.pos = vec4<f32>(p0.xy, 0.0, 1.0);         // NDC y up = the image's top row: no flip
    o.attr = vec4<f32>(p0.z, p0.w, p1.x, p1.y);
    o.b = p1.z;
    return o;
}

// Eq. 3's halo depth d_new as the depth key in [0, ½]: ½·(d − lo)/(hi − lo)
fn halo_key(d: f32) -> f32 {
    return 0.5 * clamp((d - prm.lo) / (prm.hi - prm.lo), 0.0, 1.0);
}

struct AOut {
    @builtin(frag_depth) depth: f32,
    @location(0) hit: f32,
};

@fragment fn fs_halo_depth(i: SOut) -> AOut {
    let d = i.attr.x;
    let u = abs(2.0 * i.attr.y - 1.0);
    var key = 0.75;                               // no halo depth (GL: 3e38)
    if (prm.halos != 0u) {
        key = halo_key(d + max(0.0, u - prm.delta_t) * prm.delta_d);
    } else if (u < prm.ws + prm.aa) {
        key = halo_key(d);
    }
    var o: AOut;
    o.depth = key;
    o.hit = 1.0;
    return o;
}

struct BOut {
    @builtin(frag_depth) depth: f32,
    @location(0) d: vec2<f32>,          // δ, has
    @location(1) surf: vec4<f32>,       // colour, coverage
};

@fragment fn fs_surface(i: SOut) -> BOut {
    let d = i.attr.x;
    let u = abs(2.0 * i.attr.y - 1.0);
    if (!(u < prm.ws + prm.aa)) {
        discard;
    }
    let full = u < prm.ws;
    let dn = clamp((d - prm.d_lo) / (prm.d_hi - prm.d_lo), 0.0, 1.0);
    var o: BOut;
    o.depth = select(0.5, 0.0, full) + 0.4999 * dn;
    var cov = 1.0;
    if (prm.aa > 0.0) {
        cov = min(1.0, max(0.0, (prm.ws + prm.aa - u) / (2.0 * prm.aa)));
    }
    o.d = vec2<f32>(d, 1.0);
    o.surf = vec4<f32>(i.attr.z, i.attr.w, i.b, cov);
    return o;
}

// --- C: resolve and composite -----------------------------------------------------------------

@group(1) @binding(5) var hit_tex: texture_2d<f32>;
@group(1) @binding(6) var min_tex: texture_depth_2d;
@group(1) @binding(7) var d_tex: texture_2d<f32>;
@group(1) @binding(8) var surf_tex: texture_2d<f32>;
@group(1) @binding(9) var acc_tex: texture_2d<f32>;
@group(1) @binding(10) var cls_tex: texture_2d<i32>;

@vertex fn vs_full(@builtin(vertex_index) k: u32) -> @builtin(position) vec4<f32> {
    let x = f32(k & 1u) * 4.0 - 1.0;
    let y = f32(k >> 1u) * 4.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

struct COut {
    @location(0) acc: vec4<f32>,        // colour (straight-alpha weighted), opacity
    @location(1) cls: i32,              // carved 3, surface 2, halo 1; the maximum
};

// A hit voxel with a surface fragment of depth δ is SURFACE iff δ ≤ minD + ε (MATH.md §5.4),
// else CARVED; without one, HALO. acc ← acc·(1 − a) + a·(colour, 1) with a = α (coverage 1)
// or 1 − (1 − α)^c for a surface voxel, the halo opacity for a halo voxel (0: not drawn).
@fragment fn fs_resolve(@builtin(position) fp: vec4<f32>) -> COut {
    let p = vec2<i32>(fp.xy);
    let prev = textureLoad(acc_tex, p, 0);
    let cprev = textureLoad(cls_tex, p, 0).x;
    var o: COut;
    o.acc = prev;
    o.cls = cprev;
    if (textureLoad(hit_tex, p, 0).x < 0.5) {
        return o;
    }
    let sd = textureLoad(d_tex, p, 0).xy;
    let has = sd.y > 0.5;
    let vis = has && halo_key(sd.x) <= textureLoad(min_tex, p, 0) + prm.eps_key;
    o.cls = max(cprev, select(select(1, 3, has), 2, vis));
    var rgb = prm.halo_rgb;
    var a = prm.halo_alpha;
    if (vis) {
        let s = textureLoad(surf_tex, p, 0);
        rgb = s.rgb;
        a = select(1.0 - pow(1.0 - prm.alpha, s.a), prm.alpha, s.a == 1.0);
    } else if (!(prm.halo_alpha > 0.0)) {
        return o;
    }
    o.acc = vec4<f32>(rgb * a + prev.rgb * (1.0 - a), a + prev.a * (1.0 - a));
    return o;
}
