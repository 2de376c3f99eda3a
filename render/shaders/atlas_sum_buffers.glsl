// What the accessibility's sums read (the rays' steps too): the D directions, per patch texel
// of the chunk the directions whose ray from it was found blocked, and per texel the
// directions it faces (the transpose of the rays step's FacingMasks,
// render/lighting/ao/atlas_tables.py); both u_direction_words words a texel, bit d % 32 of
// word d / 32 for direction d.
layout(std430, binding = 8) readonly buffer Directions { vec4 directions[]; };  // the D ray directions
layout(std430, binding = 10) buffer BlockedDirections { uint blocked_directions[]; };  // chunk x P^2 x u_direction_words
layout(std430, binding = 17) readonly buffer FacingDirections { uint facing_directions[]; };  // P^2 x u_direction_words

uniform int u_directions;
uniform int u_direction_words;  // ceil(D / 32)
