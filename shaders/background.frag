#version 330 core
// Neutral studio backdrop: a soft vertical gradient with a gentle vignette (same in every slot).
in vec2 v_uv;
uniform vec3 u_top;
uniform vec3 u_bottom;
out vec4 frag_color;
void main() {
    float t = smoothstep(0.0, 1.0, v_uv.y);
    vec3 c = mix(u_bottom, u_top, t);
    vec2 d = (v_uv - vec2(0.5, 0.55)) * vec2(1.2, 1.0);
    c *= 1.0 - 0.22 * smoothstep(0.25, 0.9, length(d));
    frag_color = vec4(c, 1.0);
}
