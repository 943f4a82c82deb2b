// The character: blendshape deformation (GPU_DEFORM) or pre-deformed vertices
// (CPU path), head pose, and per-material shading.
#version 330 core

#ifdef VERTEX_SHADER
#ifdef GPU_DEFORM
#include "blendshapes.glsl"
#endif
#ifdef ELASTIC_DEFORM
#include "elastic.glsl"
#endif

in vec3 in_position;   // neutral (GPU path) or already deformed (CPU path), character units
in vec3 in_normal;     // neutral or deformed, not necessarily unit length
in vec3 in_color;      // albedo, linear RGB
in vec3 in_material;   // kind code, specular, shininess
in float in_opacity;   // 1 on surfaces; the fade of a thin layer (renderer.vertex_opacity)

uniform mat4 u_model;           // head pose about the pivot
uniform mat4 u_view_projection;

out vec3 v_world;
out vec3 v_normal;
out vec3 v_color;
flat out vec3 v_material;
out float v_opacity;

void main() {
    vec3 position = in_position;
    vec3 normal = in_normal;
#ifdef GPU_DEFORM
    apply_blendshapes(gl_VertexID, position, normal);
#endif
#ifdef ELASTIC_DEFORM
    apply_elastic(gl_VertexID, position, normal);
#endif
    vec4 world = u_model * vec4(position, 1.0);
    v_world = world.xyz;
    // The pose is a rotation plus a translation: its upper 3x3 turns normals too.
    v_normal = mat3(u_model) * normalize(normal);
    v_color = in_color;
    v_material = in_material;
    v_opacity = in_opacity;
    gl_Position = u_view_projection * world;
}
#endif

#ifdef FRAGMENT_SHADER
#include "lighting.glsl"

uniform vec3 u_eye;

in vec3 v_world;
in vec3 v_normal;
in vec3 v_color;
flat in vec3 v_material;
in float v_opacity;

out vec4 f_color;

void main() {
    vec3 v = normalize(u_eye - v_world);
    vec3 n = normalize(v_normal);
    // Two-sided lighting: open meshes (mouth socket, eyelids) show their back faces.
    if (dot(n, v) < 0.0) n = -n;
    int kind = int(v_material.x + 0.5);
    vec3 color = shade(v_color, kind, v_material.y, v_material.z, n, v);
    // Thin layers (lashes, eye occlusion, films) are drawn last, see-through by their per-vertex opacity.
    f_color = vec4(to_display(color), v_opacity);
}
#endif
