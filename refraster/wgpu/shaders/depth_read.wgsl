// The depth buffer read back as float32 (refraster.wgpu, raster.depth_format "unorm24" /
// "unorm16"): WebGPU cannot copy a depth24plus texture to a buffer, but every depth format can be
// bound as a texture_depth_2d and read with textureLoad, which returns the stored value as a
// float — k / (2^n − 1) for an n-bit unorm format. One full-screen triangle, one r32float target.

@group(0) @binding(0) var stored: texture_depth_2d;

@vertex fn vs_full(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32((i << 1u) & 2u);      // 0, 2, 0
    let y = f32(i & 2u);              // 0, 0, 2
    return vec4<f32>(2.0 * x - 1.0, 1.0 - 2.0 * y, 0.0, 1.0);
}

@fragment fn fs_depth(@builtin(position) p: vec4<f32>) -> @location(0) f32 {
    return textureLoad(stored, vec2<i32>(p.xy), 0);
}
