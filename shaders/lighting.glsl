// Studio lighting shared by every slot: soft key, cool fill, rim, hemisphere ambient. Included (pasted
// after the #version line by studyapp.render.renderer.skinned_program) into skinned.frag, which lights
// every pixel, and into skinned.vert when VERTEX_LIGHTING is defined (software rasterisers: see
// Renderer). Colours are sRGB; lighting is done in linear space and tone-mapped back.

const vec3 KEY_DIR = normalize(vec3(-0.55, 0.75, 0.85));
const vec3 KEY_COL = vec3(1.00, 0.95, 0.88) * 2.3;
const vec3 FILL_DIR = normalize(vec3(0.80, 0.25, 0.70));
const vec3 FILL_COL = vec3(0.80, 0.87, 1.00) * 0.75;
const vec3 RIM_DIR = normalize(vec3(0.25, 0.55, -1.00));
const vec3 RIM_COL = vec3(1.00, 0.98, 0.95) * 1.6;
const vec3 SKY = vec3(0.62, 0.68, 0.78);
const vec3 GROUND = vec3(0.32, 0.29, 0.27);

vec3 to_linear(vec3 c) { return pow(max(c, 0.0), vec3(2.2)); }

vec3 tonemap(vec3 x) {
    // ACES filmic fit (Narkowicz), then display gamma
    x *= 0.8;
    vec3 y = clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
    return pow(y, vec3(1.0 / 2.2));
}

// The light reaching a surface, split so that the albedo can be applied later (per pixel, where a
// texture gives it): colour = albedo * diffuse + rim * mix(albedo, 0.5, 0.5) + spec.
struct Light { vec3 diffuse; vec3 rim; vec3 spec; };

// n, v: unit normal and unit direction to the eye; shading: wrap, shininess, specular strength.
Light light_at(vec3 n, vec3 v, vec3 shading, int material) {
    float wrap = shading.x, shin = shading.y, spec_k = shading.z;
    float nk = dot(n, KEY_DIR);
    float dk = max((nk + wrap) / (1.0 + wrap), 0.0);
    float df = max((dot(n, FILL_DIR) + wrap) / (1.0 + wrap), 0.0);
    vec3 diffuse = KEY_COL * dk + FILL_COL * df;
    if (material == 0) {
        // a touch of warm scattering at the light terminator reads as skin
        diffuse += KEY_COL * vec3(0.25, 0.06, 0.03) * max(1.0 - abs(nk) * 2.0, 0.0);
    }
    vec3 hemi = mix(GROUND, SKY, 0.5 + 0.5 * n.y) * 0.55;
    float f1 = 1.0 - max(dot(n, v), 0.0);
    float fres = f1 * f1 * f1;
    vec3 rim = RIM_COL * fres * max(dot(n, RIM_DIR) + 0.3, 0.0) * 0.6;
    vec3 h = normalize(KEY_DIR + v);
    float spec = pow(max(dot(n, h), 0.0), shin) * spec_k * (shin + 8.0) / 25.0;
    return Light(diffuse + hemi, rim, KEY_COL * spec * 0.5);
}

vec3 lit(Light l, vec3 albedo) { return albedo * l.diffuse + l.rim * mix(albedo, vec3(0.5), 0.5) + l.spec; }
