// The page's shaders (GLSL ES 3.00). A frame is three steps:
//  1. IDS: each sphere (the cube's atoms, the probe) as a camera-facing octagon around its
//     silhouette; per pixel the eye ray meets the sphere exactly and is cut by the cube's
//     faces the sphere crosses (and the scene's clip planes): where a plane moves the entry
//     point the pixel shows that plane's solid cap. Out go the atom's id, the capping plane and
//     the true depth. Only this step runs once per covered pixel of every sphere (software
//     rasterisers test depth after the shader once it writes depth), so it computes no light.
//  2. SHADE: once per pixel, the surface the ids name is lit (ambient, the directional light,
//     the probe's point light, Phong), and the depth is handed on.
//  3. LINES: the backbone trace outside the cube (only where the pixel's ray misses the cube:
//     the cube is a window onto its atoms), the cube's edges and the force arrow, as quads a
//     few pixels wide, depth-tested against what step 2 handed on.

import { CUBE_WINDOW, LIGHT_TERMS } from "sasprobe/glsl.js"; // render/shaders' own text

export const MAX_PLANES = 14; // the cube's 6 faces, then up to 8 clip planes of the scene
export const TABLE_WIDTH = 2048; // atoms per row of the atom tables (textures)
// Spheres and line segments are drawn as plain triangles, their data repeated for each
// vertex: SwiftShader spends about 20 µs on each instance of an instanced draw (8,000 trace
// segments: 160 ms), and a plain draw of the same triangles about 0.6 µs a segment.
export const SPHERE_VERTICES = 18; // the octagon around a sphere: 6 triangles
export const SEGMENT_VERTICES = 6; // the quad along a segment: 2 triangles

const HEAD = `#version 300 es
precision highp float;
precision highp int;
precision highp isampler2D;
`;

export const SPHERE_VERTEX = `${HEAD}
layout(location = 0) in vec4 a_sphere;  // centre (Å), radius
layout(location = 1) in ivec2 a_ids;    // atom (-2: the probe), the cube faces it crosses (-1: never cut)
uniform mat4 u_viewproj;
uniform vec3 u_eye;
out vec3 v_point;
flat out vec4 v_sphere;
flat out ivec2 v_ids;

const float OCTAGON = 1.0823922;  // 1 / cos(pi / 8): the octagon around a circle of radius 1

void main() {
  v_sphere = a_sphere;
  v_ids = a_ids;
  vec3 to_eye = u_eye - a_sphere.xyz;
  float d = length(to_eye);
  float r = a_sphere.w;
  if (d <= r * 1.0001) {  // the eye inside: no ray starts in front of the sphere
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  // The octagon in the plane through the centre square to the eye, around the circle where
  // the eye's tangent cone crosses that plane (radius r d / sqrt(d^2 - r^2)): its projection
  // holds the sphere's. Strip order 0 1 7 2 6 3 5 4 of the octagon's corners, k along the strip.
  int j = gl_VertexID % ${SPHERE_VERTICES};  // triangle j / 3 is the strip's (0 1 2), (1 2 3), ...
  int k = j / 3 + j % 3;
  int corner = (k & 1) == 1 ? (k + 1) / 2 : (8 - k / 2) % 8;
  float angle = (float(corner) + 0.5) * 0.78539816;
  vec3 w = to_eye / d;
  vec3 u = normalize(cross(w, abs(w.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0)));
  vec3 v = cross(w, u);
  float s = r * d / sqrt(d * d - r * r) * OCTAGON;
  v_point = a_sphere.xyz + (cos(angle) * u + sin(angle) * v) * s;
  gl_Position = u_viewproj * vec4(v_point, 1.0);
}`;

export const SPHERE_FRAGMENT = `${HEAD}
uniform mat4 u_viewproj;
uniform vec3 u_eye;
uniform vec4 u_planes[${MAX_PLANES}];  // n . x + w >= 0 is kept (unit n, Å)
uniform int u_n_planes;
in vec3 v_point;
flat in vec4 v_sphere;
flat in ivec2 v_ids;
layout(location = 0) out ivec2 o_ids;  // atom, the plane that caps it (-1: its own surface)

void main() {
  vec3 d = normalize(v_point - u_eye);
  vec3 oc = v_sphere.xyz - u_eye;
  float b = dot(oc, d);
  vec3 off = oc - b * d;  // no b^2 - c cancellation
  float h = v_sphere.w * v_sphere.w - dot(off, off);
  if (h < 0.0) discard;
  h = sqrt(h);
  float t0 = b - h;
  float t1 = b + h;
  int plane = -1;
  int faces = v_ids.y;
  if (faces != -1) {
    for (int i = 0; i < u_n_planes; ++i) {
      if (i < 6 && (faces & (1 << i)) == 0) continue;  // a face it does not cross
      vec4 p = u_planes[i];
      float dn = dot(p.xyz, d);
      float s = dot(p.xyz, u_eye) + p.w;
      if (dn == 0.0) {
        if (s < 0.0) discard;
        continue;
      }
      float tp = -s / dn;
      if (dn > 0.0) {
        if (tp > t0) { t0 = tp; plane = i; }
      } else {
        t1 = min(t1, tp);
      }
    }
  }
  if (t0 > t1 || t0 <= 0.0) discard;
  vec4 clip = u_viewproj * vec4(u_eye + t0 * d, 1.0);
  gl_FragDepth = 0.5 * clip.z / clip.w + 0.5;
  o_ids = ivec2(v_ids.x, plane);
}`;

export const FULLSCREEN_VERTEX = `${HEAD}
void main() {
  vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1));
  gl_Position = vec4(p, 0.0, 1.0);
}`;

export const SHADE_FRAGMENT = `${HEAD}
uniform isampler2D u_ids;
uniform sampler2D u_depth;
uniform sampler2D u_atoms;   // centre, radius of every atom, TABLE_WIDTH a row
uniform sampler2D u_colors;  // its colour
uniform vec2 u_size;
uniform vec3 u_eye;
uniform vec3 u_forward;      // the ray through the picture's centre
uniform vec3 u_right_t;      // added per unit of NDC x
uniform vec3 u_up_t;         // added per unit of NDC y
uniform vec4 u_planes[${MAX_PLANES}];
uniform vec4 u_probe;
uniform int u_touched;
uniform vec3 u_background;
uniform vec3 u_highlight;
uniform vec3 u_probe_color;
uniform vec3 u_light_dir;    // the direction the light travels (unit, world)
uniform int u_probe_light;
uniform float u_ambient;
uniform float u_directional;
uniform float u_probe_intensity;
out vec4 o_color;
${LIGHT_TERMS}

void main() {
  ivec2 px = ivec2(gl_FragCoord.xy);
  ivec2 ids = texelFetch(u_ids, px, 0).xy;
  if (ids.x == -1) {
    o_color = vec4(u_background, 1.0);
    gl_FragDepth = 1.0;
    return;
  }
  gl_FragDepth = texelFetch(u_depth, px, 0).r;
  vec2 ndc = gl_FragCoord.xy / u_size * 2.0 - 1.0;
  vec3 d = normalize(u_forward + ndc.x * u_right_t + ndc.y * u_up_t);
  ivec2 row = ivec2(ids.x % ${TABLE_WIDTH}, ids.x / ${TABLE_WIDTH});
  vec4 sphere = ids.x == -2 ? u_probe : texelFetch(u_atoms, row, 0);
  vec3 oc = sphere.xyz - u_eye;
  float b = dot(oc, d);
  vec3 off = oc - b * d;
  float t = b - sqrt(max(sphere.w * sphere.w - dot(off, off), 0.0));
  vec3 n;
  if (ids.y >= 0) {  // a cap: the plane's outward normal
    vec4 p = u_planes[ids.y];
    t = -(dot(p.xyz, u_eye) + p.w) / dot(p.xyz, d);
    n = -p.xyz;
  }
  vec3 p = u_eye + t * d;
  if (ids.y < 0) n = (p - sphere.xyz) / sphere.w;
  vec3 v = -d;
  if (ids.x == -2) {  // the light source itself: bright, lightly shaded
    o_color = vec4(u_probe_color * (0.75 + 0.25 * max(dot(n, v), 0.0)), 1.0);
    return;
  }
  vec3 albedo = texelFetch(u_colors, row, 0).rgb;
  if (ids.x == u_touched) albedo = mix(albedo, u_highlight, 0.6);
  vec3 color = u_ambient * albedo + u_directional * phong(albedo, n, v, -u_light_dir);
  if (u_probe_light == 1) {
    vec3 to_probe = u_probe.xyz - p;
    float dist = length(to_probe);
    color += u_probe_intensity * probe_attenuation(dist) * phong(albedo, n, v, to_probe / max(dist, 1e-6));
  }
  o_color = vec4(min(color, vec3(1.0)), 1.0);
}`;

export const LINE_VERTEX = `${HEAD}
layout(location = 0) in vec3 a_from;
layout(location = 1) in vec3 a_to;
layout(location = 2) in vec3 a_color;
uniform mat4 u_viewproj;
uniform vec2 u_size;
uniform float u_width_px;   // at least this wide
uniform float u_width_A;    // ... and this wide in Å where that is more
uniform float u_focal;      // the projection's 1 / tan(half the vertical field of view)
uniform float u_near;       // segments reaching behind the near plane are not drawn
uniform vec3 u_eye;
uniform vec3 u_forward;
uniform vec3 u_right_t;
uniform vec3 u_up_t;
uniform int u_window;       // 1: not where the pixel's ray meets the cube (the trace)
out vec3 v_point;
out vec3 v_color;
out float v_across;
flat out vec3 v_tangent;
${CUBE_WINDOW}

// A corner of the quad: the end's clip position moved across the segment by half its width.
vec4 widened(vec4 c, vec2 across, float side) {
  float width = max(u_width_px, u_width_A * u_focal * u_size.y * 0.5 / c.w);  // px per Å at w
  c.xy += across * side * width / u_size * c.w;
  return c;
}

bool in_window(vec4 c) {
  vec2 ndc = c.xy / c.w;
  return ray_meets_cube(u_eye, normalize(u_forward + ndc.x * u_right_t + ndc.y * u_up_t));
}

void main() {
  int j = gl_VertexID % ${SEGMENT_VERTICES};  // the strip (from, from, to, to) as 2 triangles
  int k = j / 3 + j % 3;
  int end = k >> 1;
  float side = float(k & 1) * 2.0 - 1.0;
  vec4 c0 = u_viewproj * vec4(a_from, 1.0);
  vec4 c1 = u_viewproj * vec4(a_to, 1.0);
  v_color = a_color;
  v_across = side;
  v_tangent = normalize(a_to - a_from + vec3(1e-9));
  v_point = end == 0 ? a_from : a_to;
  if (c0.w < u_near || c1.w < u_near) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  vec2 s0 = c0.xy / c0.w * u_size;
  vec2 s1 = c1.xy / c1.w * u_size;
  vec2 along = s1 - s0;
  along = dot(along, along) > 1e-12 ? normalize(along) : vec2(1.0, 0.0);
  vec2 across = vec2(-along.y, along.x);
  gl_Position = widened(end == 0 ? c0 : c1, across, side);
  // The cube's picture is convex: a quad whose four corners are in it has every pixel in it,
  // and the fragment shader would discard them all. Each vertex of the quad decides alike.
  if (u_window == 1 && in_window(widened(c0, across, -1.0)) && in_window(widened(c0, across, 1.0))
      && in_window(widened(c1, across, -1.0)) && in_window(widened(c1, across, 1.0)))
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
}`;

export const LINE_FRAGMENT = `${HEAD}
uniform vec3 u_eye;
uniform vec2 u_size;
uniform vec3 u_forward;
uniform vec3 u_right_t;
uniform vec3 u_up_t;
uniform int u_window;       // 1: not where the pixel's ray meets the cube (the trace)
uniform vec4 u_planes[${MAX_PLANES}];
uniform int u_n_planes;
uniform int u_tube;         // 1: shaded as a thin tube, 0: flat colour
uniform vec3 u_light_dir;
uniform float u_ambient;
uniform float u_directional;
in vec3 v_point;
in vec3 v_color;
in float v_across;
flat in vec3 v_tangent;
out vec4 o_color;
${CUBE_WINDOW}

void main() {
  for (int i = 6; i < u_n_planes; ++i)
    if (dot(u_planes[i].xyz, v_point) + u_planes[i].w < 0.0) discard;
  vec2 ndc = gl_FragCoord.xy / u_size * 2.0 - 1.0;
  vec3 d = normalize(u_forward + ndc.x * u_right_t + ndc.y * u_up_t);
  if (u_window == 1 && ray_meets_cube(u_eye, d)) discard;
  if (u_tube == 0) {
    o_color = vec4(v_color, 1.0);
    return;
  }
  vec3 side = cross(v_tangent, -d);
  vec3 n = -d;
  if (length(side) > 1e-6) {
    side = normalize(side);
    vec3 facing = normalize(cross(side, v_tangent));
    float a = clamp(v_across, -1.0, 1.0);
    n = normalize(facing * sqrt(max(1.0 - a * a, 0.0)) + side * a);
    if (dot(n, d) > 0.0) n = -n;
  }
  vec3 color = u_ambient * v_color + u_directional * max(dot(n, -u_light_dir), 0.0) * v_color;
  o_color = vec4(min(color, vec3(1.0)), 1.0);
}`;
