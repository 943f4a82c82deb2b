// Elastic control-point deformation (Yano & Harada 2009) in the vertex shader.
//
// Per vertex, K kept basis functions: texel (vertex * K + j) of u_basis holds
// (gradient.xyz, weight) of the j-th kept control point, and the same texel of
// u_basis_index holds that control point's index (a float, exact for small
// integers). Per frame only u_controls (N_CONTROLS displacements) is uploaded.
// K, N_CONTROLS and ELASTIC_TEXTURE_WIDTH are injected by the loader.

uniform sampler2D u_basis;
uniform sampler2D u_basis_index;
uniform vec3 u_controls[N_CONTROLS];

ivec2 elastic_texel(int index) {
    return ivec2(index % ELASTIC_TEXTURE_WIDTH, index / ELASTIC_TEXTURE_WIDTH);
}

// x = x0 + sum_j b_j u_j              (Yano & Harada eq. 5, k terms)
// n = n0 - sum_j g_j (n0 . u_j)       (first-order normal change; renormalised by the caller)
void apply_elastic(int vertex, inout vec3 position, inout vec3 normal) {
    vec3 n0 = normalize(normal);
    for (int j = 0; j < K; ++j) {
        ivec2 texel = elastic_texel(vertex * K + j);
        vec4 basis = texelFetch(u_basis, texel, 0);
        int control = int(texelFetch(u_basis_index, texel, 0).r + 0.5);
        vec3 u = u_controls[control];
        position += basis.w * u;
        normal -= basis.xyz * dot(n0, u);
    }
}
