#version 330 core
// First FXAA pass: marks the pixels fxaa.frag would change (luma range of the pixel and its diagonal
// neighbours above the threshold) by writing depth 1, every other pixel depth 0. The second pass is
// depth-tested against these marks: llvmpipe runs shader branches for all pixels of a block regardless,
// but skips blocks whose pixels all fail the early depth test, so the costly edge search runs only near
// edges. Must match the neighbourhood and threshold of fxaa.frag.
in vec2 v_uv;
uniform sampler2D u_image;
uniform vec2 u_texel;
uniform vec4 u_rect;
uniform vec4 u_bounds;

float luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }
vec3 pix(ivec2 p, ivec4 box) { return texelFetch(u_image, clamp(p, box.xy, box.zw), 0).rgb; }

void main() {
    vec2 uv = u_rect.xy + v_uv * u_rect.zw;
    ivec2 p = ivec2(uv / u_texel);
    ivec4 box = ivec4(u_bounds / u_texel.xyxy);
    float lnw = luma(pix(p + ivec2(-1, -1), box)), lne = luma(pix(p + ivec2(1, -1), box));
    float lsw = luma(pix(p + ivec2(-1, 1), box)), lse = luma(pix(p + ivec2(1, 1), box));
    float lm = luma(pix(p, box));
    float lmin = min(lm, min(min(lnw, lne), min(lsw, lse)));
    float lmax = max(lm, max(max(lnw, lne), max(lsw, lse)));
    gl_FragDepth = (lmax - lmin < 0.04) ? 0.0 : 1.0;
}
