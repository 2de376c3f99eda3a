// Packets of typed arrays with a JSON header (web/packets.py says the layout): `SPK1`, a
// little-endian uint32 header length, the header, then the arrays, each on 8 bytes.
const TYPES = { f8: Float64Array, f4: Float32Array, i4: Int32Array, u4: Uint32Array, u2: Uint16Array, u1: Uint8Array };

export function readPacket(buffer) {
  const bytes = new Uint8Array(buffer);
  if (String.fromCharCode(...bytes.subarray(0, 4)) !== "SPK1") throw new Error("not a packet");
  const length = new DataView(buffer).getUint32(4, true);
  const header = JSON.parse(new TextDecoder().decode(bytes.subarray(8, 8 + length)));
  const start = 8 + length;
  const arrays = {};
  for (const a of header.arrays)
    arrays[a.name] = new TYPES[a.dtype](buffer, start + a.offset, a.count);
  delete header.arrays;
  return { header, arrays };
}
