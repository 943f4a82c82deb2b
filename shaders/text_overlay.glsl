// A pre-rendered RGBA label (the credits) drawn over the frame as a screen-space quad.
#version 330 core

#ifdef VERTEX_SHADER
in vec2 in_position;   // normalised device coordinates
in vec2 in_uv;
out vec2 v_uv;

void main() {
    v_uv = in_uv;
    gl_Position = vec4(in_position, 0.0, 1.0);
}
#endif

#ifdef FRAGMENT_SHADER
uniform sampler2D u_label;   // straight-alpha RGBA, display colours
in vec2 v_uv;
out vec4 f_color;

void main() {
    f_color = texture(u_label, v_uv);
}
#endif
