// The interface blocks of a wide line, defined once since every stage must match: what a
// line's vertex shader hands shaders/wide_line.geom (LineVertex), and what that hands each
// fragment (LineFragment: `across` and `along` the line, its tangent, the atoms at its ends).
#define LINE_VERTEX_BLOCK LineVertex { vec3 position; vec3 color; flat int id; }
#define LINE_FRAGMENT_BLOCK LineFragment { vec3 position; vec3 color; float across; float along; flat vec3 tangent; flat ivec2 ends; }
