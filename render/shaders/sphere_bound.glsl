// A camera-facing square that covers a sphere's whole silhouette, perspective-correct.
// It lies in the plane perpendicular to the eye->centre axis through the sphere's
// nearest point (distance d - r from the eye); the cone of eye rays tangent to the
// sphere cuts that plane in a circle of radius (d - r) r / sqrt(d^2 - r^2), and the
// square circumscribes that circle. Every ray through the square meets the plane before
// the sphere, so the ray-cast depth is never nearer than the square's: depth_greater.
// Returns 0 when the eye is inside the sphere (no square bounds it: the caller covers the view).
float sphere_quad(vec3 c, float r, out vec3 corners[4]) {
    vec3 axis = c - u_eye;
    float d2 = dot(axis, axis);
    float r2 = r * r;
    if (d2 <= r2 * 1.0001) return 0.0;
    float d = sqrt(d2);
    axis /= d;
    float dist = d - r;
    float half_side = dist * r / sqrt(d2 - r2) * 1.01;  // 1 % margin against rounding at the rim
    vec3 up = u_cam_basis[1];
    vec3 u = cross(axis, up);
    if (dot(u, u) < 1e-8) u = cross(axis, u_cam_basis[0]);
    u = normalize(u) * half_side;
    vec3 v = normalize(cross(u, axis)) * half_side;
    vec3 q = u_eye + axis * dist;
    corners[0] = q - u - v;
    corners[1] = q + u - v;
    corners[2] = q - u + v;
    corners[3] = q + u + v;
    return 1.0;
}
