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
// MIRROR (0 or 1), KIND (a lit material's kind, lighting.glsl), PBR (a lit material drawn by the
// glTF metallic-roughness model: 0 no, 1 yes, 2 with its metallic-roughness texture), RIM (MToon's
// rim: parametric rim and matcap), MATCAP and RIM_TEX (its matcap and multiply textures), UV_ANIM and
// UV_MASK (MToon's UV scroll and rotation, and its mask texture), OUTLINE (the outline pass of the
// material: 0 the surface, 1 world width, 2 screen width) and OUTLINE_TEX (its width texture) are
// #defines, so a variant carries no branch, texture fetch or discard it does not use. On a software rasteriser that
// is a third of the shading time, and an opaque variant without discard lets the depth test
// run before the shader (early z).
#version 330 core

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
    vec4 m_outline_color;   // MToon outline colour (linear), its lighting mix
    vec4 m_outline;         // outline width (metres, or a fraction of the view's half height), 0, 0, 0
    vec4 m_rim;             // parametric rim colour (linear), its fresnel power
    vec4 m_rim_lift;        // rim lift, rim lighting mix, 0, 0
    vec4 m_uv_anim;         // UV scroll u, v per second, rotation in radians per second, 0
    vec4 m_pbr;             // metallic, roughness, 0, 0
    vec4 m_matcap;          // matcap factor (linear), 0
};

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
#if defined(OUTLINE) && OUTLINE
// The outline pass (VRMC_materials_mtoon-1.0, as three-vrm draws it): the back faces pushed out along the
// unit normal by the width; in screen mode the width scales with the view depth, a fraction of the half height.
uniform float u_tan_half_fov;
#if OUTLINE_TEX
uniform sampler2D u_outline_texture;   // its green channel multiplies the width (linear)
#endif
#endif

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
#if defined(OUTLINE) && OUTLINE
    float width = m_outline.x;
#if OUTLINE_TEX
    width *= textureLod(u_outline_texture, in_uv, 0.0).g;
#endif
#if OUTLINE == 2
    width *= (u_view_projection * world).w * u_tan_half_fov;
#endif
    world.xyz += normalize(v_normal) * width;
    gl_Position = u_view_projection * world;
    gl_Position.z += 1e-6 * gl_Position.w;
#else
    gl_Position = u_view_projection * world;
#endif
}
#endif

#ifdef FRAGMENT_SHADER
#include "lighting.glsl"

#if !defined(ALPHA_MODE) || !defined(SHADING) || !defined(TEXTURED) || !defined(MIRROR) || !defined(KIND) \
    || !defined(PBR) || !defined(RIM) || !defined(UV_ANIM) || !defined(OUTLINE) || !defined(MATCAP) \
    || !defined(RIM_TEX) || !defined(UV_MASK)
#error "character.glsl: the variant's #defines must all be given (parts_path.material_variant)"
#endif
#define ALPHA_OPAQUE 0
#define ALPHA_MASK 1
#define ALPHA_BLEND 2
#define SHADING_LIT 0
#define SHADING_UNLIT 1
#define SHADING_TOON 2

uniform vec3 u_eye;
uniform float u_time;   // seconds, for MToon's UV animation
#if PBR == 2
uniform sampler2D u_metal_rough_texture;   // linear: roughness in green, metallic in blue
#endif
#if MATCAP
uniform mat4 u_view;                        // the matcap is looked up by the view-space normal
uniform sampler2D u_matcap_texture;        // sRGB
#endif
#if RIM_TEX
uniform sampler2D u_rim_texture;           // sRGB, multiplies the rim
#endif
#if UV_MASK
uniform sampler2D u_uv_mask_texture;       // linear: blue scales the UV animation
#endif
// The uniform environment of the metallic-roughness model (linear radiance): the reference page of the
// tests gives three.js the same one (a PMREM of a uniform colour) with a key light of radiance 1.
const vec3 ENV_RADIANCE = vec3(0.25);
const float PI = 3.14159265;
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

#if PBR
// The glTF metallic-roughness model as three.js's MeshStandardMaterial draws it: the key light (radiance 1)
// through Lambert and GGX (Smith height-correlated visibility, Schlick's Fresnel), and the uniform
// environment through the analytic split-sum fit with multiple scattering (three.js's DFGApprox).
vec3 metal_rough(vec3 base, float metal, float rough, vec3 n, vec3 v) {
    rough = clamp(rough, 0.0525, 1.0);
    vec3 diffuse = base * (1.0 - metal);
    vec3 f0 = mix(vec3(0.04), base, metal);
    vec3 l = normalize(KEY_DIR);
    vec3 h = normalize(l + v);
    float nl = clamp(dot(n, l), 0.0, 1.0);
    float nv = clamp(dot(n, v), 0.0, 1.0);
    float nh = clamp(dot(n, h), 0.0, 1.0);
    float vh = clamp(dot(v, h), 0.0, 1.0);
    float a2 = rough * rough * rough * rough;
    float fresnel = exp2((-5.55473 * vh - 6.98316) * vh);
    vec3 f = f0 * (1.0 - fresnel) + fresnel;
    float gv = nl * sqrt(a2 + (1.0 - a2) * nv * nv);
    float gl = nv * sqrt(a2 + (1.0 - a2) * nl * nl);
    float vis = 0.5 / max(gv + gl, 1e-6);
    float dd = nh * nh * (a2 - 1.0) + 1.0;
    vec3 color = nl * (diffuse + PI * f * vis * a2 / (PI * dd * dd));
    vec4 r = rough * vec4(-1.0, -0.0275, -0.572, 0.022) + vec4(1.0, 0.0425, 1.04, -0.04);
    float a004 = min(r.x * r.x, exp2(-9.28 * nv)) * r.x + r.y;
    vec2 fab = vec2(-1.04, 1.04) * a004 + r.zw;
    vec3 single = f0 * fab.x + fab.y;
    float ems = 1.0 - (fab.x + fab.y);
    vec3 favg = f0 + (1.0 - f0) * 0.047619;
    vec3 multi = single * favg / (1.0 - ems * favg) * ems;
    vec3 total = single + multi;
    color += ENV_RADIANCE * (single + multi + diffuse * (1.0 - max(max(total.r, total.g), total.b)));
    return color;
}
#endif

void main() {
    vec4 texel = vec4(1.0);
#if UV_ANIM
    // MToon's UV animation: a turn about the texture's centre, then a scroll (before the texture transform)
#if UV_MASK
    float anim_mask = texture(u_uv_mask_texture, v_uv).b;
#else
    float anim_mask = 1.0;
#endif
    float phase = m_uv_anim.z * u_time * anim_mask;
    vec2 centred = v_uv - 0.5;
    vec2 anim_uv = vec2(cos(phase) * centred.x + sin(phase) * centred.y,
                        -sin(phase) * centred.x + cos(phase) * centred.y) + 0.5
                   + m_uv_anim.xy * u_time * anim_mask;
#else
    vec2 anim_uv = v_uv;
#endif
    vec3 uv1 = vec3(anim_uv, 1.0);
    vec2 uv = vec2(dot(m_uv_row0.xyz, uv1), dot(m_uv_row1.xyz, uv1));
#if TEXTURED
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
#if RIM
    // parametric rim and matcap, times the rim texture; the lighting mix takes the key light's radiance, 1,
    // so the rim adds as it is
    vec3 v = normalize(u_eye - v_world);
    vec3 rim = m_rim.rgb * pow(clamp(1.0 - dot(v, n) + m_rim_lift.x, 0.0, 1.0), m_rim.a);
#if MATCAP
    vec3 view_n = normalize(mat3(u_view) * n);
    vec3 view_v = normalize(mat3(u_view) * v);
    vec3 mx = normalize(vec3(view_v.z, 0.0, -view_v.x));
    vec3 my = cross(view_v, mx);
    rim += m_matcap.rgb * texture(u_matcap_texture, 0.5 + 0.5 * vec2(dot(mx, view_n), -dot(my, view_n))).rgb;
#endif
#if RIM_TEX
    rim *= texture(u_rim_texture, uv).rgb;
#endif
    color += rim;
#endif
#else
    vec3 v = normalize(u_eye - v_world);
    if (dot(n, v) < 0.0) n = -n;
#if PBR
    vec2 mr = m_pbr.xy;
#if PBR == 2
    mr *= texture(u_metal_rough_texture, uv).bg;
#endif
    vec3 color = metal_rough(base.rgb, mr.x, mr.y, n, v);
#else
    vec3 color = shade(base.rgb, KIND, m_mirror_light.z, m_mirror_light.w, n, v);
#endif
#endif
#endif
    color += m_emissive_cutoff.rgb;
#if OUTLINE
    color = m_outline_color.rgb * mix(vec3(1.0), color, m_outline_color.a);
#endif
    f_color = vec4(linear_to_srgb(color), alpha);
}
#endif
