// Perspective-correct interpolation at the sample, done in the shader (SAMPLE_INTERP, included
// by the fragment shaders of the multisampled G-buffers and of the clip surfaces at sample
// rate; the corners from sample_corners.glsl). Measured on llvmpipe (Mesa 22.3.6): under
// sample shading (GL_SAMPLE_SHADING, `sample in`, interpolateAtSample alike) a `smooth` input
// is its a/w at the sample divided by 1/w at the pixel centre (off by up to 0.06), and a
// `noperspective` input is NaN or far off on triangles its clipper cuts, at any rate;
// gl_FragCoord.xy is the sample's position. So: λ the screen-space barycentrics of
// gl_FragCoord.xy in the corners' window positions, b_i = (λ_i / w_i) / Σ_j λ_j / w_j, and
// each attribute Σ b_i a_i of the corners' values.
flat in vec3 gs_corner_win[3];     // window x, y and 1/w of each corner
flat in vec3 gs_corner_eye[3];
flat in vec3 gs_corner_normal[3];

// the attribute with corner values `corner` at the sample (bary from sample_interp)
vec3 at_sample(vec3 bary, vec3 corner[3]) {
    return bary.x * corner[0] + bary.y * corner[1] + bary.z * corner[2];
}

// the inputs at window point p (the sample's, or the clip program's centroid point)
void sample_interp_at(vec2 p, out vec3 eye, out vec3 normal, out vec3 bary) {
#ifdef FAULT_MSAA_DIVIDE_AT_CENTRE
    // planted fault: the interpolation left to llvmpipe (its divide by the centre's 1/w)
    eye = gs_eye; normal = gs_normal; bary = gs_bary;
    return;
#endif
    vec2 a = gs_corner_win[0].xy - p, b = gs_corner_win[1].xy - p, c = gs_corner_win[2].xy - p;
    vec3 l = vec3(b.x * c.y - b.y * c.x, c.x * a.y - c.y * a.x, a.x * b.y - a.y * b.x);
    vec3 q = l * vec3(gs_corner_win[0].z, gs_corner_win[1].z, gs_corner_win[2].z);
    bary = q / (q.x + q.y + q.z);
    eye = at_sample(bary, gs_corner_eye);
    normal = at_sample(bary, gs_corner_normal);
}

void sample_interp(out vec3 eye, out vec3 normal, out vec3 bary) {
    sample_interp_at(gl_FragCoord.xy, eye, normal, bary);
}
