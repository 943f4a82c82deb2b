// Studio lighting for a face: key, fill and rim directional lights plus a
// sky/ground ambient, with one branch per material kind (codes from
// facepuppet.runtime.model.character.MATERIAL_KINDS). Colours are linear.

const int KIND_SKIN = 0;
const int KIND_EYE = 1;
const int KIND_TEETH = 2;
const int KIND_MOUTH = 3;
const int KIND_LASHES = 4;
const int KIND_LIPS = 6;
const int KIND_OCCLUSION = 7;
const int KIND_FILM = 8;

// Directions point towards the lights, in world space (camera looks along -z).
const vec3 KEY_DIR = vec3(0.45, 0.55, 0.70);
const vec3 KEY_COLOR = vec3(1.00, 0.96, 0.90) * 1.05;
const vec3 FILL_DIR = vec3(-0.65, 0.10, 0.75);
const vec3 FILL_COLOR = vec3(0.70, 0.78, 0.95) * 0.35;
const vec3 RIM_DIR = vec3(-0.20, 0.45, -0.87);
const vec3 RIM_COLOR = vec3(0.90, 0.92, 1.00) * 0.55;
const vec3 SKY = vec3(0.20, 0.21, 0.24);
const vec3 GROUND = vec3(0.10, 0.08, 0.07);

// Wrapped Lambert: light reaches a little past the terminator (soft skin look).
float wrap_diffuse(vec3 n, vec3 l, float wrap) {
    return max((dot(n, l) + wrap) / (1.0 + wrap), 0.0);
}

float blinn(vec3 n, vec3 l, vec3 v, float shininess) {
    vec3 h = normalize(l + v);
    return pow(max(dot(n, h), 0.0), shininess) * step(0.0, dot(n, l));
}

vec3 light_one(vec3 albedo, vec3 n, vec3 v, vec3 dir, vec3 color, float wrap, float specular, float shininess) {
    vec3 l = normalize(dir);
    return color * (albedo * wrap_diffuse(n, l, wrap) + specular * blinn(n, l, v, shininess));
}

// n, v: unit normal and unit direction to the eye, world space.
vec3 shade(vec3 albedo, int kind, float specular, float shininess, vec3 n, vec3 v) {
    float wrap = 0.0;
    float ambient = 1.0;
    float light = 1.0;
    if (kind == KIND_SKIN) {
        wrap = 0.35;
    } else if (kind == KIND_EYE) {
        specular = max(specular, 0.8);
        shininess = max(shininess, 90.0);
    } else if (kind == KIND_TEETH) {
        wrap = 0.2;
        specular = max(specular, 0.25);
        ambient = 0.6;
        light = 0.8;
    } else if (kind == KIND_MOUTH) {
        ambient = 0.35;
        light = 0.3;
        specular *= 0.3;
    } else if (kind == KIND_LASHES) {
        albedo = min(albedo, vec3(0.06, 0.05, 0.045));
        specular = 0.05;
    } else if (kind == KIND_OCCLUSION) {
        return albedo * 0.2;  // a shadow: no light of its own
    } else if (kind == KIND_FILM) {
        wrap = 0.3;
        specular = max(specular, 0.6);
        shininess = max(shininess, 60.0);
    } else if (kind == KIND_LIPS) {
        wrap = 0.3;
        specular = max(specular, 0.3);
        shininess = max(shininess, 30.0);
    }
    vec3 hemi = mix(GROUND, SKY, 0.5 + 0.5 * n.y);
    vec3 color = ambient * albedo * hemi;
    color += light * light_one(albedo, n, v, KEY_DIR, KEY_COLOR, wrap, specular, shininess);
    color += light * FILL_COLOR * albedo * wrap_diffuse(n, normalize(FILL_DIR), wrap);  // the fill has no highlight
    color += light * light_one(albedo, n, v, RIM_DIR, RIM_COLOR, 0.0, specular * 0.5, shininess);
    return color;
}

vec3 to_display(vec3 linear) {
    // Soft shoulder then gamma 2.2 (display sRGB).
    vec3 mapped = linear / (1.0 + 0.15 * linear);
    return pow(clamp(mapped, 0.0, 1.0), vec3(1.0 / 2.2));
}
