#version 330 core
in vec2 v_uv;
uniform sampler2D u_text;   // alpha coverage of the rasterised label
uniform vec4 u_color;
out vec4 frag_color;
void main() { frag_color = vec4(u_color.rgb, u_color.a * texture(u_text, v_uv).r); }
