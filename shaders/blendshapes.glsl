// Blendshape deformation in the vertex shader.
//
// The deltas of every shape live in one RGB32UI texture of width DELTA_TEXTURE_WIDTH;
// texel index = shape * N_VERTICES + vertex. A texel holds the six delta components
// (position x y z, normal x y z) as 16-bit offsets q = round(d / s * 32767) + 32768, two
// per word, low half first; s is the shape's largest |component| of that kind
// (runtime/render/paths/deltas.py, delta_texture). q = 32768 is exactly zero.
// Per frame only the active shapes are uploaded: u_active_count pairs of shape index and
// (position, normal) weight, each weight already multiplied by the shape's step s / 32767.
// MAX_ACTIVE, N_VERTICES and DELTA_TEXTURE_WIDTH are injected by the loader.

uniform usampler2D u_deltas;
uniform int u_active_count;
uniform int u_active_shape[MAX_ACTIVE];
uniform vec2 u_active_weight[MAX_ACTIVE];

ivec2 delta_texel(int shape, int vertex) {
    int index = shape * N_VERTICES + vertex;
    return ivec2(index % DELTA_TEXTURE_WIDTH, index / DELTA_TEXTURE_WIDTH);
}

// x = x0 + sum_s w_s d_s ; n = n0 + sum_s w_s e_s (renormalised by the caller).
// One texel fetch per active shape: on a software rasteriser the fetches are the whole cost of the sum.
void apply_blendshapes(int vertex, inout vec3 position, inout vec3 normal) {
    for (int i = 0; i < u_active_count; ++i) {
        uvec3 t = texelFetch(u_deltas, delta_texel(u_active_shape[i], vertex), 0).xyz;
        vec2 w = u_active_weight[i];
        position += w.x * (vec3(uvec3(t.x & 0xFFFFu, t.x >> 16u, t.y & 0xFFFFu)) - 32768.0);
        normal += w.y * (vec3(uvec3(t.y >> 16u, t.z & 0xFFFFu, t.z >> 16u)) - 32768.0);
    }
}
