// The operator's panel (runtime/panel): Dear ImGui's triangles drawn over the frame.
// Vertices are ImDrawVert: position in framebuffer pixels (origin top left), texture
// coordinate into the font atlas (or another texture), colour as 4 bytes RGBA.
#version 330 core

#ifdef VERTEX_SHADER
in vec2 in_position;   // pixels, y down
in vec2 in_uv;
in vec4 in_color;      // unsigned bytes, normalised to 0..1 by the vertex format

uniform vec2 u_display_pos;    // ImDrawData.DisplayPos
uniform vec2 u_display_size;   // ImDrawData.DisplaySize

out vec2 v_uv;
out vec4 v_color;

void main() {
    v_uv = in_uv;
    v_color = in_color;
    vec2 p = (in_position - u_display_pos) / u_display_size;  // 0..1, y down
    gl_Position = vec4(p.x * 2.0 - 1.0, 1.0 - p.y * 2.0, 0.0, 1.0);
}
#endif

#ifdef FRAGMENT_SHADER
in vec2 v_uv;
in vec4 v_color;
uniform sampler2D u_texture;
out vec4 f_color;

void main() {
    f_color = v_color * texture(u_texture, v_uv);
}
#endif
