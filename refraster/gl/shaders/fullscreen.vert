// One triangle covering the viewport (refraster.gl full-screen passes): no vertex buffer,
// positions from gl_VertexID; the fragment stages read their inputs with texelFetch at
// ivec2(gl_FragCoord.xy).
#version 330 core

void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
