#version 330 core
// FXAA (Lottes' compact variant): edge anti-aliasing in one pass, used instead of MSAA on software
// rasterisers where multisampling triples the frame time.
in vec2 v_uv;
uniform sampler2D u_image;
uniform vec2 u_texel;  // 1 / image size
uniform vec4 u_rect;   // this slot in the image: uv origin (xy) and size (zw)
uniform vec4 u_bounds; // uv of the slot's outermost pixel centres: samples never cross into a neighbour
out vec4 frag_color;

const float REDUCE_MIN = 1.0 / 128.0;
const float REDUCE_MUL = 1.0 / 8.0;
const float SPAN_MAX = 8.0;

float luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }

vec3 tap(vec2 uv) { return texture(u_image, clamp(uv, u_bounds.xy, u_bounds.zw)).rgb; }

// the five neighbourhood taps are exact texels: texelFetch is much cheaper than filtering on llvmpipe
vec3 pix(ivec2 p, ivec4 box) { return texelFetch(u_image, clamp(p, box.xy, box.zw), 0).rgb; }

void main() {
    vec2 uv = u_rect.xy + v_uv * u_rect.zw;
    ivec2 p = ivec2(uv / u_texel);
    ivec4 box = ivec4(u_bounds / u_texel.xyxy);
    vec3 nw = pix(p + ivec2(-1, -1), box);
    vec3 ne = pix(p + ivec2(1, -1), box);
    vec3 sw = pix(p + ivec2(-1, 1), box);
    vec3 se = pix(p + ivec2(1, 1), box);
    vec3 m = pix(p, box);
    float lnw = luma(nw), lne = luma(ne), lsw = luma(sw), lse = luma(se), lm = luma(m);
    float lmin = min(lm, min(min(lnw, lne), min(lsw, lse)));
    float lmax = max(lm, max(max(lnw, lne), max(lsw, lse)));
    if (lmax - lmin < 0.04) { frag_color = vec4(m, 1.0); return; }  // flat area: leave it alone
    vec2 dir = vec2(-((lnw + lne) - (lsw + lse)), (lnw + lsw) - (lne + lse));
    float reduce = max((lnw + lne + lsw + lse) * 0.25 * REDUCE_MUL, REDUCE_MIN);
    float rcp_min = 1.0 / (min(abs(dir.x), abs(dir.y)) + reduce);
    dir = clamp(dir * rcp_min, vec2(-SPAN_MAX), vec2(SPAN_MAX)) * u_texel;
    vec3 a = 0.5 * (tap(uv + dir * (1.0 / 3.0 - 0.5)) +
                    tap(uv + dir * (2.0 / 3.0 - 0.5)));
    vec3 b = a * 0.5 + 0.25 * (tap(uv - dir * 0.5) + tap(uv + dir * 0.5));
    float lb = luma(b);
    frag_color = vec4((lb < lmin || lb > lmax) ? a : b, 1.0);
}
