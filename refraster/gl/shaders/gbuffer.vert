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
    if (u_ndc_y_down) clip.y = -clip.y;
    gl_Position = clip;
    vs_eye = (u_mv * vec4(in_pos, 1.0)).xyz;
    vs_obj = in_pos;
    vs_normal = in_normal;
#ifdef VDS
    vs_T = (u_tmat * vec4(in_pos, 1.0)).xyz;   // affine: interpolates exactly (perspective-correct)
#endif
}
