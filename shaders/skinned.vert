#version 330 core
// Linear-blend skinning + ARKit morph targets on the GPU, GL 3.3 core (no SSBOs).
// The bone palette of the slot being drawn is a uniform block (one buffer per slot; std140 mat4 array).
// Morph deltas live in a float texture indexed by (morph * rows + vertex's morph row), only for
// vertices some morph moves; the CPU sends the list of morphs whose weight is non-zero this frame.

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

out vec3 v_world;
out vec3 v_normal;
out vec3 v_albedo;
flat out vec3 v_shading;
flat out int v_material;
out vec2 v_uv;

const int MORPH_TEX_W = 2048;

mat4 bone(int j) { return u_bones[j]; }

void main() {
    vec3 p = in_position;
    vec3 n = in_normal;
    if (in_morph_row >= 0) {
        for (int i = 0; i < u_morph_count; ++i) {
            int idx = u_morph_ids[i] * u_morph_rows + in_morph_row;
            ivec2 tc = ivec2(idx % MORPH_TEX_W, idx / MORPH_TEX_W);
            p += u_morph_w[i] * texelFetch(u_morph_pos, tc, 0).xyz;
            n += u_morph_w[i] * texelFetch(u_morph_nrm, tc, 0).xyz;
        }
    }
    // most vertices follow one or two bones; skipping zero weights saves work on CPU rasterisers
    mat4 skin = in_weights.x * bone(in_joints.x);
    if (in_weights.y > 0.0) skin += in_weights.y * bone(in_joints.y);
    if (in_weights.z > 0.0) skin += in_weights.z * bone(in_joints.z);
    if (in_weights.w > 0.0) skin += in_weights.w * bone(in_joints.w);
    vec4 world = u_model * skin * vec4(p, 1.0);
    v_world = world.xyz;
    v_normal = mat3(u_model) * mat3(skin) * n;
    v_albedo = in_color.rgb;
    v_material = int(in_color.a + 0.5);
    v_shading = in_shading;
    v_uv = in_uv;
    gl_Position = u_view_proj * world;
}
