// Tables that shaders read entry by entry, stored in images rather than storage buffers:
// llvmpipe loads a vec4 from an image far faster than from a storage buffer, which it
// reads lane by lane and a component at a time (docs/rendering.md, "Tables in images"). TABLE_ROW entries a row (render/gl/textures.py table_image): entry
// k at (k % TABLE_ROW, k / TABLE_ROW).
#define TABLE_ROW_BITS 12

ivec2 table_texel(uint k) { return ivec2(int(k & ((1u << TABLE_ROW_BITS) - 1u)), int(k >> TABLE_ROW_BITS)); }
