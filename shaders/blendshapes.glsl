// Blendshape deformation in the vertex shader.
//
// Deltas of every shape live in two float textures (positions, normals) of
// width DELTA_TEXTURE_WIDTH; texel index = shape * N_VERTICES + vertex.
// Per frame only the active shapes are uploaded: u_active_count pairs of
// (shape index, weight). MAX_ACTIVE and N_VERTICES are injected by the loader.

uniform sampler2D u_delta_positions;
uniform sampler2D u_delta_normals;
uniform int u_active_count;
uniform int u_active_shape[MAX_ACTIVE];
uniform float u_active_weight[MAX_ACTIVE];

ivec2 delta_texel(int shape, int vertex) {
    int index = shape * N_VERTICES + vertex;
    return ivec2(index % DELTA_TEXTURE_WIDTH, index / DELTA_TEXTURE_WIDTH);
}

// x = x0 + sum_s w_s d_s ; n = n0 + sum_s w_s e_s (renormalised by the caller)
void apply_blendshapes(int vertex, inout vec3 position, inout vec3 normal) {
    for (int i = 0; i < u_active_count; ++i) {
        ivec2 texel = delta_texel(u_active_shape[i], vertex);
        float w = u_active_weight[i];
        position += w * texelFetch(u_delta_positions, texel, 0).xyz;
        normal += w * texelFetch(u_delta_normals, texel, 0).xyz;
    }
}
