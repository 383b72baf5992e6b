// World-space line vertices → clip space with one float32 matrix P·V (refraster.gl).
#version 330 core

uniform mat4 u_mvp;
in vec3 in_pos;

void main() { gl_Position = u_mvp * vec4(in_pos, 1.0); }
