// A character with glTF / VRM parts (runtime.character_parts): morph targets
// (GPU_DEFORM), linear blend skinning (SKIN), textured base colour with the
// glTF material model (lit, unlit, MToon-style toon), alpha MASK / BLEND,
// emissive. Characters without parts are drawn by face.glsl, as before.
//
// Colour: textures are sRGB8_ALPHA8 (the sampler decodes to linear), factors
// and vertex colours are linear, lighting is linear, the output is encoded
// to sRGB (no tone curve; linear_to_srgb), so an unlit texel shows as itself.
//
// The fragment stage is compiled once per material variant (parts_path.material_variant):
// ALPHA_MODE (0 opaque, 1 mask, 2 blend), SHADING (0 lit, 1 unlit, 2 toon), TEXTURED and
// MIRROR (0 or 1) and KIND (a lit material's kind, lighting.glsl) are #defines, so a variant
// carries no branch, texture fetch or discard it does not use. On a software rasteriser that
// is a third of the shading time, and an opaque variant without discard lets the depth test
// run before the shader (early z).
#version 330 core

#ifdef VERTEX_SHADER
#ifdef GPU_DEFORM
#include "blendshapes.glsl"
#endif

in vec3 in_position;   // rest pose, world space (GPU path) or already deformed and skinned (CPU path)
in vec3 in_normal;
in vec3 in_color;      // COLOR_0, linear RGB
in vec2 in_uv;         // TEXCOORD_0, origin top-left
in float in_opacity;   // multiplies the alpha: the fade of an OBJ rig's thin layers (1 elsewhere)
#ifdef SKIN
in vec4 in_joints;     // node indices (exact small integers as floats)
in vec4 in_weights;
// Skinning matrices D_j (Skeleton.pose_matrices), one node per 4 texels of a row: texel (4j + c, 0) = column c.
uniform sampler2D u_joints;

mat4 joint(float j) {
    int x = 4 * int(j + 0.5);
    return mat4(texelFetch(u_joints, ivec2(x, 0), 0), texelFetch(u_joints, ivec2(x + 1, 0), 0),
                texelFetch(u_joints, ivec2(x + 2, 0), 0), texelFetch(u_joints, ivec2(x + 3, 0), 0));
}
#endif

uniform mat4 u_model;           // whole-character translation (and, without a skeleton, the head pose)
uniform mat4 u_view_projection;

out vec3 v_world;
out vec3 v_normal;
out vec3 v_color;
out vec2 v_uv;
out float v_opacity;

void main() {
    vec3 position = in_position;
    vec3 normal = in_normal;
#ifdef GPU_DEFORM
    apply_blendshapes(gl_VertexID, position, normal);   // morphs first, in the rest pose (glTF order)
#endif
#ifdef SKIN
    mat4 skin = in_weights.x * joint(in_joints.x) + in_weights.y * joint(in_joints.y)
              + in_weights.z * joint(in_joints.z) + in_weights.w * joint(in_joints.w);
    position = (skin * vec4(position, 1.0)).xyz;
    normal = mat3(skin) * normal;
#endif
    vec4 world = u_model * vec4(position, 1.0);
    v_world = world.xyz;
    v_normal = mat3(u_model) * normal;
    v_color = in_color;
    v_uv = in_uv;
    v_opacity = in_opacity;
    gl_Position = u_view_projection * world;
}
#endif

#ifdef FRAGMENT_SHADER
#include "lighting.glsl"

#if !defined(ALPHA_MODE) || !defined(SHADING) || !defined(TEXTURED) || !defined(MIRROR) || !defined(KIND)
#error "character.glsl: ALPHA_MODE, SHADING, TEXTURED, MIRROR and KIND must be defined (parts_path.material_variant)"
#endif
#define ALPHA_OPAQUE 0
#define ALPHA_MASK 1
#define ALPHA_BLEND 2
#define SHADING_LIT 0
#define SHADING_UNLIT 1
#define SHADING_TOON 2

uniform vec3 u_eye;
// The material of this draw call: one uniform buffer per material (runtime/render/parts_path.py).
layout(std140) uniform Material {
    vec4 m_base_color;      // baseColorFactor, linear RGBA
    vec4 m_emissive_cutoff; // emissiveFactor (linear), alphaCutoff
    vec4 m_shade_shift;     // MToon shade colour (linear), shading shift
    vec4 m_modes;           // alpha mode, shading code, shading toony, has texture (the first two and the
                            // last are also the variant's #defines)
    vec4 m_mirror_light;    // mirrored wrap s, t (done here; the sampler clamps), specular, shininess
    vec4 m_uv_row0;         // KHR_texture_transform T * R * S, first two rows
    vec4 m_uv_row1;
};
uniform sampler2D u_base_texture;

in vec3 v_world;
in vec3 v_normal;
in vec3 v_color;
in vec2 v_uv;
in float v_opacity;

out vec4 f_color;

// sRGB encoding. Above the linear toe, 1.055 c^(1/2.4) - 0.055 is replaced by a fit in square roots
// (c^(1/2), c^(1/4), c^(1/8), c; least squares on [0.0031308, 1], exact at 1): at most 0.019 of an
// 8-bit step off, the same byte for 99.6 % of values and one step off for the rest. Three square
// roots cost a fraction of pow's log2/exp2 per channel on a software rasteriser (~1 ms a frame at
// 1280x720 with MSAA on llvmpipe).
vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    vec3 s1 = sqrt(c);
    vec3 s2 = sqrt(s1);
    vec3 s3 = sqrt(s2);
    vec3 curve = 0.643054 * s1 + 0.711755 * s2 - 0.336833 * s3 - 0.017976 * c;
    return mix(c * 12.92, curve, step(0.0031308, c));
}

vec2 mirror(vec2 uv) {
    vec2 m = mod(uv, 2.0);
    vec2 folded = mix(m, 2.0 - m, step(1.0, m));
    return mix(uv, folded, m_mirror_light.xy);
}

// MToon-style toon shading (VRMC_materials_mtoon-1.0): a key light's N.L shifted by the shading
// shift, then a linear step of width (1 - toony) * 2 about 0 between the shade and the lit colour.
// The shade colour multiplies the base texture (VRM 0.x avatars mostly use the main texture as shade texture).
vec3 toon(vec3 lit_color, vec3 shade_color, vec3 n) {
    float shading = dot(n, normalize(KEY_DIR)) + m_shade_shift.a;
    float toony = clamp(m_modes.z, 0.0, 0.999);
    float t = clamp((shading - (-1.0 + toony)) / ((1.0 - toony) - (-1.0 + toony)), 0.0, 1.0);
    return mix(shade_color, lit_color, t);
}

void main() {
    vec4 texel = vec4(1.0);
#if TEXTURED
    vec3 uv1 = vec3(v_uv, 1.0);
    vec2 uv = vec2(dot(m_uv_row0.xyz, uv1), dot(m_uv_row1.xyz, uv1));
#if MIRROR
    texel = textureGrad(u_base_texture, mirror(uv), dFdx(uv), dFdy(uv));  // derivatives of the unfolded uv
#else
    texel = texture(u_base_texture, uv);
#endif
#endif
    vec4 base = m_base_color * vec4(v_color, v_opacity) * texel;
#if ALPHA_MODE == ALPHA_MASK
    if (base.a < m_emissive_cutoff.a) discard;
#endif
#if ALPHA_MODE == ALPHA_BLEND
    float alpha = base.a;
#else
    float alpha = 1.0;
#endif

#if SHADING == SHADING_UNLIT
    vec3 color = base.rgb;
#else
    vec3 n = normalize(v_normal);
    // A double-sided surface seen from behind is lit as its back face (glTF: the normal is reversed).
    if (!gl_FrontFacing) n = -n;
#if SHADING == SHADING_TOON
    vec3 color = toon(base.rgb, m_shade_shift.rgb * v_color * texel.rgb, n);
#else
    vec3 v = normalize(u_eye - v_world);
    if (dot(n, v) < 0.0) n = -n;
    vec3 color = shade(base.rgb, KIND, m_mirror_light.z, m_mirror_light.w, n, v);
#endif
#endif
    color += m_emissive_cutoff.rgb;
    f_color = vec4(linear_to_srgb(color), alpha);
}
#endif
