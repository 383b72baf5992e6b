// Clip-surface vertex stage (refraster.gl; Trapp & Döllner 2.5D clip surfaces).
// As gbuffer.vert, plus the world position the clip test (Eq. 1, evaluated in world space:
// the scene's `evaluation_space`) and the cap shading read. Solids are drawn with their
// draw's model matrix, caps (already in world space) with the identity.
#version 330 core

uniform mat4 u_mvp;        // projection · view · model (uploaded column-major)
uniform mat4 u_mv;         // view · model
uniform mat4 u_model;      // model (object → world)

in vec3 in_pos;
in vec3 in_normal;

out vec3 vs_eye;
out vec3 vs_obj;
out vec3 vs_normal;
out vec3 vs_world;

void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
    vs_eye = (u_mv * vec4(in_pos, 1.0)).xyz;
    vs_obj = in_pos;
    vs_normal = in_normal;
    vs_world = (u_model * vec4(in_pos, 1.0)).xyz;   // affine: interpolates perspective-correctly
}
