// 2.5D clip surfaces with caps of refraster.wgpu (Trapp & Döllner Sec. 3-5, Listing 1;
// MATH.md §1.1, §1.2, §1.2b, §2.2). Compiled as one module after gbuffer.wgsl (its Draw, VOut,
// vs, headlight, unit_normal, ids_record, surface_record): the driver's vertex stage with the
// Draw's tmat set to the model matrix (solids) or the identity (caps, already in world space), so
// VOut.tex is the world position P.
//
// One fragment body (clip_fragment), three entry points for the G-buffer's three passes of at
// most 32 bytes per sample (fs_clip_ids, fs_clip_surface, fs_clip_shade), each drawing the
// solids, then the caps, from a cleared depth buffer with the same state:
//   solids (flags.y = 0): Listing 1 - discard where an enabled surface has g(P) < 0;
//   caps   (flags.y = 1): the displaced grid of surface flags.z over one solid: discard where
//          that solid's parity test says outside, or another enabled surface clips; shaded
//          from the derived normal and occlusion maps (or the user's normal, light, diffuse).
//
// Every map is filtered here, bilinearly, from textureLoad of an rgba32float texture: core
// WebGPU filters float32 textures only with the optional feature float32-filterable, and a
// sampler's address modes would be fixed per bind group anyway. The filter is OpenGL's
// GL_LINEAR (texel centres at (i + ½)/n, row i of the package's map at t ∈ [i/h, (i+1)/h), no
// flip) with the surface's address mode applied to each of the four texel indices:
// 0 repeat, 1 clamp-to-edge, 2 mirrored repeat (the package's "wrap").
// Planted faults (tests only): WRONG_ADDRESS_MODE, PARITY_FAR_END.

override WRONG_ADDRESS_MODE: bool = false;  // planted fault: clamp-to-edge ↔ repeat
override PARITY_FAR_END: bool = false;      // planted fault: the parity count from the far end

struct ClipSurface {
    origin: vec4<f32>,     // O (world), w: 1 if enabled
    uh: vec4<f32>,         // Û, w: |U|
    vh: vec4<f32>,         // V̂, w: |V|
    n: vec4<f32>,          // N = Û × V̂
    scale: vec4<f32>,      // Sx, Sy, Sz, w: the address mode (0 repeat, 1 clamp, 2 mirrored)
};
struct Clip {
    surfaces: array<ClipSurface, 2>,
    view_nmat: mat4x4<f32>,   // inverse(view[:3, :3])ᵀ in the upper 3 × 3
    smat: mat4x4<f32>,        // the cap's solid's sprite_matrix: world → T ∈ [0, 1]³
    cap_color: vec4<f32>,
    flags: vec4<i32>,         // surfaces, cap (0/1), the cap's surface, user maps (1 diffuse,
                              // 2 normal, 4 light)
};
@group(1) @binding(20) var<uniform> clip: Clip;
@group(1) @binding(21) var offset0: texture_2d<f32>;         // surface 0's offset map (R)
@group(1) @binding(22) var offset1: texture_2d<f32>;         // surface 1's
@group(1) @binding(23) var cap_depth: texture_2d_array<f32>; // the solid's sprite layers
@group(1) @binding(24) var cap_count: texture_2d<i32>;       // and counts
@group(1) @binding(25) var cap_shading: texture_2d<f32>;     // derived normal (Û, V̂, N), occlusion
@group(1) @binding(26) var cap_diffuse: texture_2d<f32>;     // user diffuse (RGB)
@group(1) @binding(27) var cap_normal: texture_2d<f32>;      // user normal, 0.5·n + 0.5 (RGB)
@group(1) @binding(28) var cap_light: texture_2d<f32>;       // user light map (R)

fn address(i: i32, n: i32, mode: i32) -> i32 {
    var m = mode;
    if (WRONG_ADDRESS_MODE) {
        m = select(1, 0, mode == 1);
    }
    if (m == 1) {
        return clamp(i, 0, n - 1);
    }
    if (m == 0) {
        return ((i % n) + n) % n;
    }
    let p = ((i % (2 * n)) + 2 * n) % (2 * n);       // mirrored repeat: period 2n
    return select(p, 2 * n - 1 - p, p >= n);
}

fn bilinear(tex: texture_2d<f32>, st: vec2<f32>, mode: i32) -> vec4<f32> {
    let size = vec2<i32>(textureDimensions(tex));
    let p = st * vec2<f32>(size) - 0.5;
    let f = floor(p);
    let a = p - f;
    let i0 = vec2<i32>(f);
    let x0 = address(i0.x, size.x, mode);
    let x1 = address(i0.x + 1, size.x, mode);
    let y0 = address(i0.y, size.y, mode);
    let y1 = address(i0.y + 1, size.y, mode);
    let top = mix(textureLoad(tex, vec2<i32>(x0, y0), 0), textureLoad(tex, vec2<i32>(x1, y0), 0),
                  a.x);
    let bottom = mix(textureLoad(tex, vec2<i32>(x0, y1), 0),
                     textureLoad(tex, vec2<i32>(x1, y1), 0), a.x);
    return mix(top, bottom, a.y);
}

fn surface_mode(k: i32) -> i32 {
    return i32(clip.surfaces[k].scale.w);
}

// Eq. 2: the surface's texture coordinates of P
fn surface_st(k: i32, p: vec3<f32>) -> vec2<f32> {
    let c = clip.surfaces[k];
    let d = p - c.origin.xyz;
    return vec2<f32>((dot(d, c.uh.xyz) / c.uh.w) * c.scale.x,
                     (dot(d, c.vh.xyz) / c.vh.w) * c.scale.y);
}

// Listing 1 / Eq. 1: g(P) = N·(P − O) + Sz·OM(s, t); the fragment is clipped iff g < 0
fn clipped(k: i32, p: vec3<f32>) -> bool {
    let c = clip.surfaces[k];
    if (c.origin.w == 0.0) {
        return false;
    }
    let st = surface_st(k, p);
    var om: f32;
    if (k == 0) {
        om = bilinear(offset0, st, surface_mode(k)).r;
    } else {
        om = bilinear(offset1, st, surface_mode(k)).r;
    }
    return dot(c.n.xyz, p - c.origin.xyz) + c.scale.z * om < 0.0;
}

// the volumetric parity test (MATH.md §2.2) as gbuffer.wgsl's parity_inside, over the cap's
// solid's sprite: layers counted front to back until the first one behind T.z
fn cap_inside(t: vec3<f32>) -> bool {
    if (any(t < vec3<f32>(0.0)) || any(t > vec3<f32>(1.0))) {
        return false;
    }
    let size = vec2<i32>(textureDimensions(cap_count));
    let col = min(i32(t.x * f32(size.x)), size.x - 1);
    let row = min(i32(t.y * f32(size.y)), size.y - 1);
    let n = textureLoad(cap_count, vec2<i32>(col, row), 0).r;
    var count = 0;
    for (var j = 0; j < n; j = j + 1) {
        var layer = j;
        if (PARITY_FAR_END) {
            layer = n - 1 - j;
        }
        if (textureLoad(cap_depth, vec2<i32>(col, row), layer, 0).r <= t.z) {
            count = count + 1;
        } else {
            break;
        }
    }
    return (count & 1) == 1;
}

struct ClipFrag {
    n: vec3<f32>,
    c: vec3<f32>,
};

fn clip_fragment(i: VOut) -> ClipFrag {
    let p = i.tex;
    let cap = clip.flags.y == 1;
    let ck = clip.flags.z;
    for (var k = 0; k < 2; k = k + 1) {
        if (k >= clip.flags.x) {
            break;
        }
        if (cap && k == ck) {
            continue;                     // a cap is never clipped by its own surface
        }
        if (clipped(k, p)) {
            discard;
        }
    }
    var o: ClipFrag;
    if (!cap) {
        o.n = unit_normal(i);
        o.c = headlight(i).xyz;
        return o;
    }
    if (!cap_inside((clip.smat * vec4<f32>(p, 1.0)).xyz)) {
        discard;
    }
    let s = clip.surfaces[ck];
    let mode = surface_mode(ck);
    let st = surface_st(ck, p);
    let sh = bilinear(cap_shading, st, mode);
    var frame = sh.xyz;
    if ((clip.flags.w & 2) != 0) {
        let e = 2.0 * bilinear(cap_normal, st, mode).xyz - 1.0;
        frame = vec3<f32>(e.x, e.y, -e.z);          // z of the encoding points along −N
    }
    var light = sh.w;
    if ((clip.flags.w & 4) != 0) {
        light = bilinear(cap_light, st, mode).r;
    }
    let nw = frame.x * s.uh.xyz + frame.y * s.vh.xyz + frame.z * s.n.xyz;
    let m3 = mat3x3<f32>(clip.view_nmat[0].xyz, clip.view_nmat[1].xyz, clip.view_nmat[2].xyz);
    var n = m3 * nw;
    let len = length(n);
    if (len > 0.0) {
        n = n / len;
    }
    let el = max(length(i.eye), 1e-30);
    let shade = light * (0.25 + 0.75 * abs(dot(n, i.eye)) / el);
    var base = clip.cap_color.xyz;
    if ((clip.flags.w & 1) != 0) {
        base = bilinear(cap_diffuse, st, mode).xyz;
    }
    o.n = n;
    o.c = clamp(base * shade, vec3<f32>(0.0), vec3<f32>(1.0));
    return o;
}

@fragment fn fs_clip_ids(i: VOut, @builtin(front_facing) front: bool) -> Ids {
    _ = clip_fragment(i);           // its discards
    return ids_record(i, front);
}

@fragment fn fs_clip_surface(i: VOut) -> Surface {
    return surface_record(i, clip_fragment(i).n);
}

@fragment fn fs_clip_shade(i: VOut) -> @location(0) vec4<f32> {
    let f = clip_fragment(i);
    return vec4<f32>(f.c, 1.0);
}
