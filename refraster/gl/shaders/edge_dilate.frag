// Edge width (refraster.gl): a grey dilation of the edge map with the disk of radius r =
// width − 1 (offsets with dx² + dy² ≤ r², as skimage.morphology.disk); texels outside the
// image are not part of the neighbourhood.
#version 330 core

uniform sampler2D u_edge;   // NEAREST
uniform int u_radius;

out vec4 o_edge;

void main() {
    ivec2 size = textureSize(u_edge, 0);
    ivec2 x = ivec2(gl_FragCoord.xy);
    vec4 best = vec4(0.0);
    for (int dy = -u_radius; dy <= u_radius; ++dy)
        for (int dx = -u_radius; dx <= u_radius; ++dx) {
            ivec2 p = x + ivec2(dx, dy);
            if (dx * dx + dy * dy > u_radius * u_radius || any(lessThan(p, ivec2(0)))
                || any(greaterThanEqual(p, size))) continue;
            best = max(best, texelFetch(u_edge, p, 0));
        }
    o_edge = best;
}
