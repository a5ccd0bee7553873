/* The binary formats the web viewer reads: plain functions over ArrayBuffers, no three.js,
 * no page. Loaded before viewer.js, which takes them from window.fgFormats. Every
 * multi-byte value is read through a DataView as little-endian, the formats' byte order,
 * whatever the machine's. */
'use strict';

(function () {
  /* The FGPC body of GET .../points (proto/openapi.yaml): a 64-byte header, f32
   * xyz[count][3], u8 rgba[count][4]; with each point's flat voxel index, ascending. */
  function parseFgpc(buf) {
    const dv = new DataView(buf);
    const magic = String.fromCharCode(...new Uint8Array(buf, 0, 4));
    if (magic !== 'FGPC' || dv.getUint32(4, true) !== 1)
      throw new Error('GET .../points: not an FGPC version 1 body');
    const hb = dv.getUint32(8, true), count = dv.getUint32(12, true);
    if (buf.byteLength !== hb + count * 16)
      throw new Error(`GET .../points: ${buf.byteLength} bytes for ${count} points`);
    const cloud = {
      count, nSolid: dv.getUint32(16, true), voxel: dv.getFloat32(20, true),
      alpha: dv.getFloat32(24, true),
      min: [dv.getFloat32(28, true), dv.getFloat32(32, true), dv.getFloat32(36, true)],
      n: [dv.getUint32(40, true), dv.getUint32(44, true), dv.getUint32(48, true)],
      xyz: new Float32Array(count * 3),
      base: new Uint8Array(count * 3),  // the field's colours, kept to undo a heatmap
      index: new Uint32Array(count),    // each point's flat voxel index, for heatmap grids
    };
    for (let i = 0; i < count * 3; i++) cloud.xyz[i] = dv.getFloat32(hb + 4 * i, true);
    const rgba = new Uint8Array(buf, hb + count * 12, count * 4);
    const [nx, ny, nz] = cloud.n;
    for (let i = 0; i < count; i++) {
      cloud.base.set(rgba.subarray(4 * i, 4 * i + 3), 3 * i);
      // centres lie at min + (i + 0.5) * voxel: floor recovers i exactly
      const v = [0, 1, 2].map((a) =>
        Math.floor((cloud.xyz[3 * i + a] - cloud.min[a]) / cloud.voxel));
      const ix = Math.min(nx - 1, Math.max(0, v[0]));
      const iy = Math.min(ny - 1, Math.max(0, v[1]));
      const iz = Math.min(nz - 1, Math.max(0, v[2]));
      cloud.index[i] = (iz * ny + iy) * nx + ix;
    }
    return cloud;
  }

  const PLY_TYPES = { char: 1, uchar: 1, short: 2, ushort: 2, int: 4, uint: 4, float: 4,
    double: 8 };

  /* A binary little-endian PLY point list with float x, y, z, uchar red, green, blue and
   * float score (POST .../heatmap with "format": "ply", lib/query/heatmap.h) into {count,
   * xyz, rgb, score}. Other properties are skipped by their size, so an added one does not
   * break the page. */
  function parsePly(buf) {
    const bytes = new Uint8Array(buf);
    const head = String.fromCharCode(...bytes.subarray(0, Math.min(bytes.length, 4096)));
    const end = head.indexOf('end_header\n');
    if (!head.startsWith('ply\n') || end < 0) throw new Error('heatmap: not a PLY body');
    const lines = head.slice(0, end).split('\n');
    if (!lines.includes('format binary_little_endian 1.0'))
      throw new Error('heatmap: not a binary little-endian PLY');
    let count = 0, size = 0;
    const at = {}; // property name -> byte offset in a vertex
    for (const l of lines) {
      const w = l.split(' ');
      if (w[0] === 'element' && w[1] === 'vertex') count = Number(w[2]);
      else if (w[0] === 'element') break; // only the vertices are read
      else if (w[0] === 'property' && w.length === 3) {
        if (!PLY_TYPES[w[1]]) throw new Error(`heatmap: PLY property type ${w[1]}`);
        at[w[2]] = { off: size, type: w[1] };
        size += PLY_TYPES[w[1]];
      }
    }
    for (const [name, type] of [['x', 'float'], ['y', 'float'], ['z', 'float'],
      ['red', 'uchar'], ['green', 'uchar'], ['blue', 'uchar'], ['score', 'float']])
      if (!at[name] || at[name].type !== type)
        throw new Error(`heatmap: the PLY has no ${type} ${name}`);
    const base = end + 'end_header\n'.length;
    if (buf.byteLength < base + count * size) throw new Error('heatmap: the PLY is cut short');
    const dv = new DataView(buf, base);
    const out = { count, xyz: new Float32Array(3 * count), rgb: new Uint8Array(3 * count),
      score: new Float32Array(count) };
    for (let k = 0, o = 0; k < count; k++, o += size) {
      out.xyz[3 * k] = dv.getFloat32(o + at.x.off, true);
      out.xyz[3 * k + 1] = dv.getFloat32(o + at.y.off, true);
      out.xyz[3 * k + 2] = dv.getFloat32(o + at.z.off, true);
      out.rgb[3 * k] = dv.getUint8(o + at.red.off);
      out.rgb[3 * k + 1] = dv.getUint8(o + at.green.off);
      out.rgb[3 * k + 2] = dv.getUint8(o + at.blue.off);
      out.score[k] = dv.getFloat32(o + at.score.off, true);
    }
    return out;
  }

  window.fgFormats = { parseFgpc, parsePly };
})();
