// Perspective-correct interpolation at the sample, done in the shader (SAMPLE_INTERP, included
// by the G-buffer fragment shaders; refraster/gl/msaa_techniques.py). Measured on llvmpipe
// (Mesa 22.3.6): under sample shading (GL_SAMPLE_SHADING, `sample in`, interpolateAtSample
// alike) a `smooth` input is its numerator at the sample divided by 1/w at the pixel centre
// (barycentrics summing to 1 ± 0.02), and `noperspective` inputs of samples 2 and 3 read NaN;
// gl_FragCoord.xy is the sample's position. So: λ the screen-space barycentrics of
// gl_FragCoord.xy in the triangle's window positions, b_i = (λ_i / w_i) / Σ_j λ_j / w_j, and
// each attribute Σ b_i a_i of the corners' values (flat inputs from gbuffer.geom).
flat in vec3 gs_corner_win[3];     // window x, y and 1/w of each corner
flat in vec3 gs_corner_eye[3];
flat in vec3 gs_corner_normal[3];

void sample_interp(out vec3 eye, out vec3 normal, out vec3 bary) {
#ifdef FAULT_MSAA_DIVIDE_AT_CENTRE
    // planted fault: the interpolation left to llvmpipe (its divide by the centre's 1/w)
    eye = gs_eye; normal = gs_normal; bary = gs_bary;
    return;
#endif
    vec2 p = gl_FragCoord.xy;
    vec2 a = gs_corner_win[0].xy - p, b = gs_corner_win[1].xy - p, c = gs_corner_win[2].xy - p;
    vec3 l = vec3(b.x * c.y - b.y * c.x, c.x * a.y - c.y * a.x, a.x * b.y - a.y * b.x);
    vec3 q = l * vec3(gs_corner_win[0].z, gs_corner_win[1].z, gs_corner_win[2].z);
    bary = q / (q.x + q.y + q.z);
    eye = bary.x * gs_corner_eye[0] + bary.y * gs_corner_eye[1] + bary.z * gs_corner_eye[2];
    normal = bary.x * gs_corner_normal[0] + bary.y * gs_corner_normal[1]
           + bary.z * gs_corner_normal[2];
}
