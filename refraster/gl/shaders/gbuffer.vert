// G-buffer and depth-peeling vertex stage (refraster.gl).
// Object-space position (and the PLY's vertex normal, when the scene is smooth) in; the
// clip-space position out, computed with one float32 matrix P·V·M as the scene package
// specifies (clip = projection @ view @ model @ [x y z 1]).
#version 330 core

uniform mat4 u_mvp;        // projection · view · model (uploaded column-major)
uniform mat4 u_mv;         // view · model
uniform vec2 u_viewport;   // width, height in pixels
uniform bool u_ndc_y_down; // raster.ndc_y = "down" (Vulkan): NDC y points down the picture;
                           // GL's points up, so the clip y is negated here (exact), before
                           // GL's clipping, window transform and facing

in vec3 in_pos;
in vec3 in_normal;

out vec3 vs_eye;           // eye-space position
out vec3 vs_obj;           // object-space position (flat normals are formed from it)
out vec3 vs_normal;        // object-space vertex normal (smooth scenes)
#ifdef VDS
uniform mat4 u_tmat;       // sprite matrix · model: object → the sprite's texture space [0, 1]³
out vec3 vs_T;
#endif

void main() {
    vec4 clip = u_mvp * vec4(in_pos, 1.0);
#ifdef FAULT_HALF_PIXEL
    // planted fault: the viewport shifted by half a pixel in x and y
    clip.xy += clip.w / u_viewport;
#endif
#ifdef FAULT_NEAR_W_CLAMPED
    // planted fault: w kept away from 0 (vertices behind the eye move in front of it)
    clip.w = max(clip.w, 1e-3);
#endif
#ifdef FAULT_GUARD_BAND_CLAMP
    // planted fault: a vertex beyond an 8x guard band clamped to it instead of clipped
    if (clip.w > 0.0) clip.xy = clamp(clip.xy, vec2(-8.0 * clip.w), vec2(8.0 * clip.w));
#endif
#ifdef FAULT_SUBPIXEL_1BIT
    // planted fault: the window position snapped to 1 sub-pixel bit (a half-pixel grid)
    if (clip.w > 0.0) {
        vec2 win = (clip.xy / clip.w * 0.5 + 0.5) * u_viewport;
        win = floor(win * 2.0 + 0.5) * 0.5;
        clip.xy = (win / u_viewport * 2.0 - 1.0) * clip.w;
    }
#endif
    if (u_ndc_y_down) clip.y = -clip.y;
    gl_Position = clip;
    vs_eye = (u_mv * vec4(in_pos, 1.0)).xyz;
    vs_obj = in_pos;
    vs_normal = in_normal;
#ifdef VDS
    vs_T = (u_tmat * vec4(in_pos, 1.0)).xyz;   // affine: interpolates exactly (perspective-correct)
#endif
}
