#version 330 core
in vec2 in_xz;
uniform mat4 u_view_proj;
out vec2 v_xz;
void main() {
    v_xz = in_xz;
    gl_Position = u_view_proj * vec4(in_xz.x, 0.0, in_xz.y, 1.0);
}
