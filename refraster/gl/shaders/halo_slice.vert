// 4D halos (Wang et al. 2013, refraster.gl): the thickened, tetrahedralized surface's vertices
// in 3D screen space — x, y already in NDC of the sliced box, z the slicing axis — with their
// attributes (4D depth δ relative to a reference value, thickness coordinate t, colour).
#version 330 core

in vec2 in_xy;
in float in_z;
in vec4 in_attr;     // δ − δ_ref, t, r, g
in float in_b;       // b

out vec2 vs_xy;
out float vs_z;
out vec4 vs_attr;
out float vs_b;
flat out int vs_id;  // the global vertex index (ties broken from the smaller one)

void main() {
    vs_xy = in_xy;
    vs_z = in_z;
    vs_attr = in_attr;
    vs_b = in_b;
    vs_id = gl_VertexID;
    gl_Position = vec4(in_xy, 0.0, 1.0);
}
