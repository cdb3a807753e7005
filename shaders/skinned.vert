#version 330 core
// Linear-blend skinning + ARKit morph targets on the GPU, GL 3.3 core (no SSBOs).
// The bone palette of the slot being drawn is a uniform block (one buffer per slot; std140 mat4 array).
// Morph deltas live in a float texture indexed by (morph * rows + vertex's morph row), only for
// vertices some morph moves; the CPU sends the list of morphs whose weight is non-zero this frame.
// With VERTEX_LIGHTING (software rasterisers) the lighting of lighting.glsl, pasted in before this, is
// done here per vertex instead of per pixel in skinned.frag.

in vec3 in_position;
in vec3 in_normal;
in vec4 in_color;        // linear rgb + material id
in vec3 in_shading;      // material: wrap, shininess, specular strength
in ivec4 in_joints;
in vec4 in_weights;
in int in_morph_row;     // -1: no morph moves this vertex
in vec2 in_uv;

const int MAX_BONES = 256;  // must match MAX_BONES in studyapp/render/gpu.py
layout(std140) uniform Bones { mat4 u_bones[MAX_BONES]; };
uniform sampler2D u_morph_pos;
uniform sampler2D u_morph_nrm;
uniform int u_morph_rows;
uniform int u_morph_count;
uniform int u_morph_ids[52];
uniform float u_morph_w[52];
uniform mat4 u_view_proj;
uniform mat4 u_model;

#ifdef VERTEX_LIGHTING
uniform vec3 u_camera_pos;
uniform vec4 u_base_factor;
out vec3 v_colour;
#ifndef UNTEXTURED  // (UNTEXTURED: the colour is all the fragment shader needs)
out vec3 v_albedo;
out vec2 v_uv;
out vec3 v_light_diffuse;
out vec3 v_light_rim;
out vec3 v_light_spec;
#endif
#else
out vec3 v_albedo;
out vec2 v_uv;
out vec3 v_world;
out vec3 v_normal;
flat out vec3 v_shading;
flat out int v_material;
#endif

const int MORPH_TEX_W = 2048;

// Specialised per group of triangles (studyapp.render.gpu.skin_groups): SKIN_BONES, the joints any vertex of
// the group is weighted to (1, 2 or 4), and NO_MORPHS where no morph moves any of them. llvmpipe runs both
// sides of every branch for 8 vertices at once, so the loop and the gathers left out here are work it would
// otherwise do (masked) for every vertex; the sums are the same.
#ifndef SKIN_BONES
#define SKIN_BONES 4
#endif

mat4 bone(int j) { return u_bones[j]; }

void main() {
    vec3 p = in_position;
    vec3 n = in_normal;
#ifndef NO_MORPHS
    if (in_morph_row >= 0) {
        for (int i = 0; i < u_morph_count; ++i) {
            int idx = u_morph_ids[i] * u_morph_rows + in_morph_row;
            ivec2 tc = ivec2(idx % MORPH_TEX_W, idx / MORPH_TEX_W);
            p += u_morph_w[i] * texelFetch(u_morph_pos, tc, 0).xyz;
            n += u_morph_w[i] * texelFetch(u_morph_nrm, tc, 0).xyz;
        }
    }
#endif
    // zero weights add nothing (a GPU skips them; the group's SKIN_BONES leaves the rest out)
    mat4 skin = in_weights.x * bone(in_joints.x);
#if SKIN_BONES > 1
    if (in_weights.y > 0.0) skin += in_weights.y * bone(in_joints.y);
#endif
#if SKIN_BONES > 2
    if (in_weights.z > 0.0) skin += in_weights.z * bone(in_joints.z);
    if (in_weights.w > 0.0) skin += in_weights.w * bone(in_joints.w);
#endif
    vec4 world = u_model * skin * vec4(p, 1.0);
    vec3 normal = mat3(u_model) * mat3(skin) * n;
#if !(defined(VERTEX_LIGHTING) && defined(UNTEXTURED))
    v_albedo = in_color.rgb;
    v_uv = in_uv;
#endif
#ifdef VERTEX_LIGHTING
    vec3 nn = normalize(normal);
    vec3 v = normalize(u_camera_pos - world.xyz);
    // (a double-sided avatar is lit per pixel: a vertex cannot tell which side will be seen)
    Light l = light_at(nn, v, in_shading, int(in_color.a + 0.5));
#ifndef UNTEXTURED
    v_light_diffuse = l.diffuse;
    v_light_rim = l.rim;
    v_light_spec = l.spec;
#endif
    v_colour = tonemap(lit(l, in_color.rgb * u_base_factor.rgb));
#else
    v_world = world.xyz;
    v_normal = normal;
    v_material = int(in_color.a + 0.5);
    v_shading = in_shading;
#endif
    gl_Position = u_view_proj * world;
}
