// Overlay points (markers, pins, drag targets) drawn over the face as round dots.
#version 330 core

#ifdef VERTEX_SHADER
in vec3 in_position;   // character units
in vec3 in_color;      // display RGB 0..1

uniform mat4 u_view_projection;
uniform float u_point_size;   // pixels

out vec3 v_color;

void main() {
    v_color = in_color;
    gl_Position = u_view_projection * vec4(in_position, 1.0);
    gl_PointSize = u_point_size;
}
#endif

#ifdef FRAGMENT_SHADER
in vec3 v_color;
out vec4 f_color;

void main() {
    vec2 d = gl_PointCoord * 2.0 - 1.0;
    float r = dot(d, d);
    if (r > 1.0) {
        discard;
    }
    // a dark rim so a dot reads on light and dark skin alike
    f_color = vec4(r > 0.55 ? vec3(0.05) : v_color, 1.0);
}
#endif
