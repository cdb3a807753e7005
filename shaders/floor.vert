#version 330 core
in vec2 in_xz;              // corner of the unit square
uniform mat4 u_view_proj;
uniform vec4 u_bounds;      // x0, z0, x1, z1 on the ground: where floor.frag draws anything visible
out vec2 v_xz;
void main() {
    v_xz = mix(u_bounds.xy, u_bounds.zw, in_xz);
    gl_Position = u_view_proj * vec4(v_xz.x, 0.0, v_xz.y, 1.0);
}
