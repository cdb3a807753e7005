#version 330 core
// The avatar's pixels: lighting (lighting.glsl, pasted in before this) per pixel, or, with
// VERTEX_LIGHTING, the colour lit per vertex by skinned.vert (and only a texture's albedo applied here);
// with UNTEXTURED as well, only that colour (on llvmpipe every varying costs set-up per tiny triangle).

#ifdef VERTEX_LIGHTING
in vec3 v_colour;        // finished colour of an untextured vertex
#ifndef UNTEXTURED
in vec3 v_albedo;        // linear colour (converted per vertex: cheaper than per pixel)
in vec2 v_uv;
in vec3 v_light_diffuse;
in vec3 v_light_rim;
in vec3 v_light_spec;
#endif
#else
in vec3 v_albedo;
in vec2 v_uv;
in vec3 v_world;
in vec3 v_normal;
flat in vec3 v_shading;  // material: wrap, shininess, specular strength
flat in int v_material;
uniform vec3 u_camera_pos;
#endif

#ifndef UNTEXTURED
uniform sampler2D u_base_color;
uniform vec4 u_base_factor;
uniform bool u_has_texture;
#endif

out vec4 frag_color;

void main() {
#if defined(VERTEX_LIGHTING) && defined(UNTEXTURED)
    frag_color = vec4(v_colour, 1.0);
#elif defined(VERTEX_LIGHTING)
    // uv < 0 marks parts of a textured avatar that have no texture
    if (u_has_texture && v_uv.x >= 0.0) {
        vec3 albedo = v_albedo * u_base_factor.rgb * to_linear(texture(u_base_color, v_uv).rgb);
        frag_color = vec4(tonemap(lit(Light(v_light_diffuse, v_light_rim, v_light_spec), albedo)), 1.0);
    } else {
        frag_color = vec4(v_colour, 1.0);
    }
#else
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    vec3 v = normalize(u_camera_pos - v_world);
    vec3 albedo = v_albedo * u_base_factor.rgb;
    if (u_has_texture && v_uv.x >= 0.0) albedo *= to_linear(texture(u_base_color, v_uv).rgb);
    frag_color = vec4(tonemap(lit(light_at(n, v, v_shading, v_material), albedo)), 1.0);
#endif
}
