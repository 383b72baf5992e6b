// Cutaway pass 1 (Burns & Finkelstein Sec. 4, refraster.gl): the rear hulls of the objects of
// interest, drawn with depth test GREATER against a depth buffer cleared to 0, so each pixel
// keeps its farthest fragment. Targets: 0 R32F window depth, 1 R32I hull index + 1 (0: none).
// Vertex stage: gbuffer.vert.
#version 330 core

uniform int u_hull;          // the cutaway object's index (per-object angles, Sec. 5.3)

layout(location = 0) out float o_depth;
layout(location = 1) out int o_hull;

void main() {
    o_depth = gl_FragCoord.z;
    o_hull = u_hull + 1;
}
