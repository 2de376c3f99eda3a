// What the accessibility's sums read (the rays' steps too): the D directions, per patch texel
// of the chunk the directions whose ray from it was found blocked, and per texel the
// directions it faces (the transpose of the rays step's FacingMasks,
// render/lighting/ao/atlas_tables.py); both u_direction_words words a texel, bit d % 32 of
// word d / 32 for direction d.
#define MAX_DIRECTIONS 1024  // render/lighting/settings.py DIRECTION_RANGE
// The D ray directions: a uniform block, which llvmpipe reads as fast as an image whatever
// index each invocation asks for (a storage buffer it reads lane by lane).
layout(std140, binding = 1) uniform Directions { vec4 directions[MAX_DIRECTIONS]; };
layout(std430, binding = 10) buffer BlockedDirections { uint blocked_directions[]; };  // chunk x P^2 x u_direction_words
layout(std430, binding = 17) readonly buffer FacingDirections { uint facing_directions[]; };  // P^2 x u_direction_words

uniform int u_directions;
uniform int u_direction_words;  // ceil(D / 32)
