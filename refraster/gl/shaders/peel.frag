// Classic depth peeling, one layer per pass (refraster.gl; Trapp & Döllner Sec. 5.2).
// Pass k draws every draw call with depth test LESS (GREATER under reversed-Z: u_reversed)
// against a cleared 32-bit float depth buffer and discards each fragment that is not strictly
// behind layer k − 1 at its pixel (a larger depth; under reversed-Z a smaller one)
// (u_prev_depth: layer k − 1's R32F copy of gl_FragCoord.z; u_prev_ids.a: its coverage).
// Targets: 0 R32F window depth, 1 RGBA32I (primitive id, object id, front facing, covered).
#version 330 core

uniform int u_object;
uniform bool u_peel;                 // false in the first pass
uniform bool u_reversed;             // depth test GREATER: layers run from the largest depth
uniform sampler2D u_prev_depth;      // NEAREST, read with texelFetch
uniform isampler2D u_prev_ids;

layout(location = 0) out float o_depth;
layout(location = 1) out ivec4 o_ids;

void main() {
    if (u_peel) {
        ivec2 p = ivec2(gl_FragCoord.xy);
        if (texelFetch(u_prev_ids, p, 0).a == 0) discard;      // no layer k − 1 here
#ifndef FAULT_PEEL_NO_DISCARD
        float prev = texelFetch(u_prev_depth, p, 0).r;
        if (u_reversed ? gl_FragCoord.z >= prev : gl_FragCoord.z <= prev) discard;
#endif
    }
    o_depth = gl_FragCoord.z;
    o_ids = ivec4(gl_PrimitiveID, u_object, gl_FrontFacing ? 1 : 0, 1);
}
