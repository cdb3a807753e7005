#version 330 core
// Floor that fades into the backdrop, with a soft contact shadow under the feet.
in vec2 v_xz;
uniform vec2 u_shadow_centre;   // ground position under the hips
uniform vec2 u_feet[2];         // ground positions of the feet
uniform vec3 u_floor;
out vec4 frag_color;
void main() {
    float r = length(v_xz / vec2(1.6, 1.1));
    float floor_a = 0.55 * (1.0 - smoothstep(0.2, 1.0, r));
    vec2 d = (v_xz - u_shadow_centre) / vec2(0.34, 0.24);
    float shadow = 0.45 * exp(-2.2 * dot(d, d));
    for (int i = 0; i < 2; ++i) {
        vec2 f = (v_xz - u_feet[i]) / vec2(0.08, 0.14);
        shadow += 0.35 * exp(-2.5 * dot(f, f));
    }
    shadow = min(shadow, 0.7);
    vec3 c = u_floor * (1.0 - shadow);
    frag_color = vec4(c, max(floor_a, shadow));
}
