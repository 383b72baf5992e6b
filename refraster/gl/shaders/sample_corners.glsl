// The corners sample_interp.glsl interpolates from, written by the geometry shaders of the
// G-buffer and clip-surface programs (SAMPLE_INTERP; the including shader declares vs_eye[],
// vs_normal[], u_nmat and u_smooth): each corner's window x, y and 1/w, eye position and
// normal, flat. Called before each EmitVertex (a shader's outputs are undefined after it).
uniform vec2 u_viewport_px;            // width, height: the window transform of the corners
flat out vec3 gs_corner_win[3];
flat out vec3 gs_corner_eye[3];
flat out vec3 gs_corner_normal[3];

void sample_corners(vec3 face) {
    for (int i = 0; i < 3; ++i) {
        vec4 c = gl_in[i].gl_Position;
        gs_corner_win[i] = vec3((c.xy / c.w * 0.5 + 0.5) * u_viewport_px, 1.0 / c.w);
        gs_corner_eye[i] = vs_eye[i];
        gs_corner_normal[i] = u_nmat * (u_smooth ? vs_normal[i] : face);
    }
}
