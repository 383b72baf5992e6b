// The G-buffer, depth peeling and the volumetric parity test of refraster.wgpu (WGSL).
//
// Core WebGPU has no geometry shader and no primitive index, so every draw is de-indexed on the
// CPU: each triangle corner is its own vertex and carries its face's attributes — the face
// index within the draw call and the flat face normal (v1 − v0) × (v2 − v0) — which reach the
// fragment with @interpolate(flat) (the three corners agree, so the provoking vertex does not
// matter). The barycentric corner is vertex_index % 3.
//
// Conventions (overridable constants, set per pipeline from the scene's "raster" object):
//   DEPTH_REMAP  the scene's projection is OpenGL's (−w ≤ z ≤ w): z' = 0.5·(z + w), so the
//                clip volume is WebGPU's 0 ≤ z' ≤ w and the window depth z'/w = 0.5·z/w + 0.5;
//   Y_SIGN       +1 when the scene's NDC y points up (WebGPU, OpenGL, Direct3D, Metal): WebGPU's
//                viewport already maps NDC y = +1 to the image's top row; −1 under ndc_y =
//                "down" (Vulkan): the clip y is negated;
//   DEPTH_CLAMP  the written window depth is clamped to [0, 1] (unclippedDepth).
// Planted faults (tests only; a normal pipeline leaves them false): HALF_PIXEL,
// SPRITE_ROWS_FLIPPED; the others are host-side (refraster/wgpu/driver.py).

override DEPTH_REMAP: bool = true;
override Y_SIGN: f32 = 1.0;
override DEPTH_CLAMP: bool = false;
override PEEL: bool = false;          // fs_peel: false in the first pass
override PEEL_GREATER: bool = false;  // fs_peel: the depth test is greater / greater-equal
override HALF_PIXEL: bool = false;    // planted fault: the viewport shifted by half a pixel
override SPRITE_ROWS_FLIPPED: bool = false;  // planted fault: the sprite's rows top-down

struct Draw {
    mvp: mat4x4<f32>,      // projection · view · model (the package's row-major matrix, transposed)
    mv: mat4x4<f32>,       // view · model
    nmat: mat4x4<f32>,     // the normal matrix inverse(view · model)[:3, :3]ᵀ in the upper 3 × 3
    tmat: mat4x4<f32>,     // sprite matrix · model (vds scenes)
    base: vec4<f32>,       // palette[object_id mod len]
    light: vec4<f32>,      // ambient, diffuse, specular, shininess
    viewport: vec2<f32>,   // width, height in pixels
    object_id: i32,
    smooth_normals: u32,   // 1: the PLY's vertex normals; 0: the face normal
};
@group(0) @binding(0) var<uniform> u: Draw;

struct VIn {
    @builtin(vertex_index) index: u32,
    @location(0) pos: vec3<f32>,
    @location(1) vnormal: vec3<f32>,
    @location(2) fnormal: vec3<f32>,
    @location(3) face: i32,
};

struct VOut {
    @builtin(position) @invariant pos: vec4<f32>,
    @location(0) eye: vec3<f32>,
    @location(1) snormal: vec3<f32>,
    @location(2) @interpolate(flat) fnormal: vec3<f32>,
    @location(3) bary: vec3<f32>,
    @location(4) tex: vec3<f32>,
    @location(5) @interpolate(flat) face: i32,
};

// the scene's clip coordinates → WebGPU's: DEPTH_REMAP, then Y_SIGN (every scene-space vertex
// stage: vs here, the cutaway's vs_line)
fn convention_clip(c: vec4<f32>) -> vec4<f32> {
    var clip = c;
    if (DEPTH_REMAP) {
        clip.z = 0.5 * (clip.z + clip.w);
    }
    clip.y = Y_SIGN * clip.y;
    return clip;
}

@vertex fn vs(v: VIn) -> VOut {
    var o: VOut;
    var clip = convention_clip(u.mvp * vec4<f32>(v.pos, 1.0));
    if (HALF_PIXEL) {
        clip.x = clip.x + clip.w / u.viewport.x;
        clip.y = clip.y + clip.w / u.viewport.y;
    }
    o.pos = clip;
    o.eye = (u.mv * vec4<f32>(v.pos, 1.0)).xyz;
    let n3 = mat3x3<f32>(u.nmat[0].xyz, u.nmat[1].xyz, u.nmat[2].xyz);
    o.snormal = n3 * v.vnormal;
    o.fnormal = n3 * v.fnormal;
    let k = v.index % 3u;
    o.bary = vec3<f32>(f32(k == 0u), f32(k == 1u), f32(k == 2u));
    o.tex = (u.tmat * vec4<f32>(v.pos, 1.0)).xyz;   // affine: perspective-correct is exact
    o.face = v.face;
    return o;
}

fn window_depth(p: vec4<f32>) -> f32 {
    if (DEPTH_CLAMP) {
        return clamp(p.z, 0.0, 1.0);
    }
    return p.z;
}

fn unit_normal(i: VOut) -> vec3<f32> {
    var n = i.fnormal;
    if (u.smooth_normals == 1u) {
        n = i.snormal;
    }
    let len = length(n);
    if (len > 0.0) {
        n = n / len;
    }
    return n;
}

// pass 1 (24 bytes per sample): window depth, eye depth, ids
struct Ids {
    @location(0) depth: f32,             // r32float
    @location(1) eye_depth: f32,         // r32float
    @location(2) ids: vec4<i32>,         // rgba32sint: face, object, front facing, covered
};
// (the techniques' G-buffer passes write the same records: ids_record, surface_record)
fn ids_record(i: VOut, front: bool) -> Ids {
    var o: Ids;
    o.depth = window_depth(i.pos);
    o.eye_depth = -i.eye.z;
    o.ids = vec4<i32>(i.face, u.object_id, select(0, 1, front), 1);
    return o;
}
@fragment fn fs_ids(i: VOut, @builtin(front_facing) front: bool) -> Ids {
    return ids_record(i, front);
}

// pass 2 (32 bytes per sample): unit normal, barycentrics
struct Surface {
    @location(0) normal: vec4<f32>,      // rgba32float
    @location(1) bary: vec4<f32>,        // rgba32float
};
fn surface_record(i: VOut, n: vec3<f32>) -> Surface {
    var o: Surface;
    o.normal = vec4<f32>(n, 0.0);
    o.bary = vec4<f32>(i.bary, 0.0);
    return o;
}
@fragment fn fs_surface(i: VOut) -> Surface {
    return surface_record(i, unit_normal(i));
}

// pass 3 (16 bytes per sample): the headlight colour of unit normal n at the fragment
// (two-sided: d = min(|n · (−e/|e|)|, 1)); the cutaway's cut surfaces pass their own normal
fn headlight_normal(i: VOut, n: vec3<f32>) -> vec4<f32> {
    let el = length(i.eye);
    var d = 1.0;
    if (el > 0.0) {
        d = min(abs(dot(n, -i.eye / el)), 1.0);
    }
    let c = u.base.xyz * (u.light.x + u.light.y * d) + u.light.z * pow(d, u.light.w);
    return vec4<f32>(clamp(c, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}
fn headlight(i: VOut) -> vec4<f32> {
    return headlight_normal(i, unit_normal(i));
}
@fragment fn fs_shade(i: VOut) -> @location(0) vec4<f32> {
    return headlight(i);
}

// pass 3 of a vds scene (20 bytes per sample): colour and the parity test (Trapp & Döllner
// Sec. 5.3, MATH.md §2.2). T = tmat · x in the sprite's texture space [0, 1]³; outside the
// unit cube → outside; else the nearest texel, and the number of layers with d_j ≤ T.z counted
// front to back until the first layer behind; odd → inside. Texture row r covers
// t ∈ [r/h, (r + 1)/h) (the package's maps, row 0 at the top, are uploaded flipped).
@group(1) @binding(0) var sprite_depth: texture_2d_array<f32>;   // r32float, textureLoad only
@group(1) @binding(1) var sprite_count: texture_2d<i32>;         // r32sint

fn parity_inside(t: vec3<f32>) -> bool {
    if (any(t < vec3<f32>(0.0)) || any(t > vec3<f32>(1.0))) {
        return false;
    }
    let size = vec2<i32>(textureDimensions(sprite_count));
    let col = min(i32(t.x * f32(size.x)), size.x - 1);
    var row = min(i32(t.y * f32(size.y)), size.y - 1);
    if (SPRITE_ROWS_FLIPPED) {
        row = size.y - 1 - row;
    }
    let n = textureLoad(sprite_count, vec2<i32>(col, row), 0).r;
    var count = 0;
    for (var j = 0; j < n; j = j + 1) {
        if (textureLoad(sprite_depth, vec2<i32>(col, row), j, 0).r <= t.z) {
            count = count + 1;
        } else {
            break;
        }
    }
    return (count & 1) == 1;
}
struct ShadeVds {
    @location(0) color: vec4<f32>,       // rgba32float
    @location(1) inside: i32,            // r32sint
};
@fragment fn fs_shade_vds(i: VOut) -> ShadeVds {
    var o: ShadeVds;
    o.color = headlight(i);
    o.inside = select(0, 1, parity_inside(i.tex));
    return o;
}

// classic depth peeling, one layer per pass (20 bytes per sample): pass k discards a fragment
// where layer k − 1 is empty or where it is not strictly behind layer k − 1 in the direction
// of the depth test (less: z ≤ previous; greater: z ≥ previous — a reversed-Z peel runs front
// to back too)
@group(1) @binding(2) var prev_depth: texture_2d<f32>;   // r32float, textureLoad only
@group(1) @binding(3) var prev_ids: texture_2d<i32>;     // rgba32sint
struct Peel {
    @location(0) depth: f32,
    @location(1) ids: vec4<i32>,
};
@fragment fn fs_peel(i: VOut, @builtin(front_facing) front: bool) -> Peel {
    let z = window_depth(i.pos);
    if (PEEL) {
        let p = vec2<i32>(i.pos.xy);
        if (textureLoad(prev_ids, p, 0).a == 0) {
            discard;
        }
        let prev = textureLoad(prev_depth, p, 0).r;
        if ((!PEEL_GREATER && z <= prev) || (PEEL_GREATER && z >= prev)) {
            discard;
        }
    }
    var o: Peel;
    o.depth = z;
    o.ids = vec4<i32>(i.face, u.object_id, select(0, 1, front), 1);
    return o;
}
