// Elastic control-point deformation (Yano & Harada 2009) in the vertex shader.
//
// Per vertex, K kept basis functions: texel (vertex * K + j) of u_basis holds
// (gradient.xyz, weight) of the j-th kept control point, and the same texel of
// u_basis_index holds that control point's index (a float, exact for small
// integers). Per frame only u_controls (N_CONTROLS displacements) is uploaded.
// Rigid parts (N_RIGID > 0, e.g. the lower teeth following the jaw): texel
// (vertex) of u_rigid_label holds part + 1 (0: none), u_rigid holds the rows of
// each part's [R | t], fitted on the CPU each frame.
// K, N_CONTROLS, N_RIGID and ELASTIC_TEXTURE_WIDTH are injected by the loader.

uniform sampler2D u_basis;
uniform sampler2D u_basis_index;
uniform vec3 u_controls[N_CONTROLS];
#if N_RIGID > 0
uniform sampler2D u_rigid_label;
uniform vec4 u_rigid[3 * N_RIGID];
#endif

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
#if N_RIGID > 0
    int part = int(texelFetch(u_rigid_label, elastic_texel(vertex), 0).r + 0.5) - 1;
    if (part >= 0) {  // x = R x0 + t, n = R n0
        vec4 p0 = vec4(position, 1.0);
        position = vec3(dot(u_rigid[3 * part], p0), dot(u_rigid[3 * part + 1], p0), dot(u_rigid[3 * part + 2], p0));
        normal = vec3(dot(u_rigid[3 * part].xyz, n0), dot(u_rigid[3 * part + 1].xyz, n0),
                      dot(u_rigid[3 * part + 2].xyz, n0));
    }
#endif
}
