#version 330 core
// Benchmark baseline: the same triangles with no skinning and no morphs.
in vec3 in_position;
uniform mat4 u_view_proj;
void main() { gl_Position = u_view_proj * vec4(in_position, 1.0); }
