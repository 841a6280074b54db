// The skin's geometry, built from the TD's skinNodes and skinCells values alone.
//
// A skinDisplacement packet carries each displaced node's vector (mm, the sensor's frame): the
// twin moves the node by it (times the page's scale), so shear and direction show as a change of
// shape. A skinDeformedDetection packet carries only the norm; from a Thing that does not declare
// skinDisplacement the twin shows it along the inward normal (how a press deforms a skin), exact
// for normal presses and an approximation for shear. Nodes absent from a packet are at rest (the
// packet is the complete deformed set; docs/processing.md), so a packet moves the nodes it names
// and returns those the previous one named to rest: nothing else changes.

export class Skin {
  constructor(skinNodes, skinCells) {
    const nodes = skinNodes.arrayOfNodes || [];
    const n = nodes.length;
    this.n = n;
    this.index = new Map(); // nodeID -> vertex index
    this.rest = new Float64Array(3 * n);
    nodes.forEach((node, k) => {
      this.index.set(node.nodeID, k);
      const p = node.nodeLocation;
      this.rest[3 * k] = p.x;
      this.rest[3 * k + 1] = p.y;
      this.rest[3 * k + 2] = p.z;
    });
    // triangles: quads and larger polygons as fans (cells are counter-clockwise from outside)
    const tri = [];
    for (const cell of skinCells.arrayOfCells || []) {
      const v = cell.connectedNodes.map((id) => this.index.get(id));
      if (v.some((k) => k === undefined)) continue; // a cell naming an unknown node: skip it
      for (let t = 1; t + 1 < v.length; t++) tri.push(v[0], v[t], v[t + 1]);
    }
    const m = tri.length / 3;
    this.cells = (skinCells.arrayOfCells || []).length;
    this.i = new Int32Array(m);
    this.j = new Int32Array(m);
    this.k = new Int32Array(m);
    for (let t = 0; t < m; t++) {
      this.i[t] = tri[3 * t];
      this.j[t] = tri[3 * t + 1];
      this.k[t] = tri[3 * t + 2];
    }
    this.normals = this._normals();
    this.intensity = new Float64Array(n);
    this.vec = new Float64Array(3 * n); // each node's displacement vector, where a packet gave one
    this.hasVec = new Uint8Array(n);
    this.x = new Float64Array(n);
    this.y = new Float64Array(n);
    this.z = new Float64Array(n);
    for (let v = 0; v < n; v++) {
      this.x[v] = this.rest[3 * v];
      this.y[v] = this.rest[3 * v + 1];
      this.z[v] = this.rest[3 * v + 2];
    }
    this.active = new Int32Array(n); // nodes deformed by the last packet: active[0 .. nActive)
    this.nActive = 0;
    this.changed = new Int32Array(n); // nodes the last apply() moved: changed[0 .. nChanged)
    this.nChanged = 0;
    this._mark = new Uint32Array(n);
    this._epoch = 0;
    this.size = this._size();
  }

  _normals() {
    // area-weighted vertex normals from the winding (outward for the hub's meshes)
    const r = this.rest;
    const acc = new Float64Array(3 * this.n);
    for (let t = 0; t < this.i.length; t++) {
      const a = this.i[t], b = this.j[t], c = this.k[t];
      const ux = r[3 * b] - r[3 * a], uy = r[3 * b + 1] - r[3 * a + 1], uz = r[3 * b + 2] - r[3 * a + 2];
      const vx = r[3 * c] - r[3 * a], vy = r[3 * c + 1] - r[3 * a + 1], vz = r[3 * c + 2] - r[3 * a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (const v of [a, b, c]) {
        acc[3 * v] += nx;
        acc[3 * v + 1] += ny;
        acc[3 * v + 2] += nz;
      }
    }
    for (let v = 0; v < this.n; v++) {
      const l = Math.hypot(acc[3 * v], acc[3 * v + 1], acc[3 * v + 2]) || 1;
      acc[3 * v] /= l;
      acc[3 * v + 1] /= l;
      acc[3 * v + 2] /= l;
    }
    return acc;
  }

  _size() {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let v = 0; v < this.n; v++) {
      for (let d = 0; d < 3; d++) {
        lo[d] = Math.min(lo[d], this.rest[3 * v + d]);
        hi[d] = Math.max(hi[d], this.rest[3 * v + d]);
      }
    }
    this.lo = lo;
    this.hi = hi;
    return this.n ? Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) : 0;
  }

  // Fixed axis ranges around the rest shape: each at least 30 % of the largest extent, so a flat
  // pad keeps room for its dents, and the view does not jump as the skin deforms.
  ranges() {
    return [0, 1, 2].map((d) => {
      const c = (this.lo[d] + this.hi[d]) / 2;
      const half = 1.05 * Math.max((this.hi[d] - this.lo[d]) / 2, 0.15 * this.size, 1e-3);
      return [c - half, c + half];
    });
  }

  // Positions and per-vertex intensity for one packet; ``scale`` exaggerates the displacement.
  // Returns the largest intensity in the packet. Only the nodes that change are touched: those
  // the packet names and those the previous packet named (back to rest), or all with ``full``;
  // their indices are ``changed[0 .. nChanged)``, for the renderer to upload just those.
  apply(packet, scale = 1, full = false) {
    const I = this.intensity, mark = this._mark, ch = this.changed, act = this.active;
    const epoch = ++this._epoch;
    let nc = 0;
    for (let a = 0; a < this.nActive; a++) {
      const k = act[a];
      I[k] = 0;
      if (mark[k] !== epoch) {
        mark[k] = epoch;
        ch[nc++] = k;
      }
    }
    let na = 0, max = 0;
    const V = this.vec, hasVec = this.hasVec;
    for (const d of packet.arrayOfDeformedNodes || []) {
      const k = this.index.get(d.deformedNodeID);
      if (k === undefined) continue;
      const v = d.deformedNodeIntensity;
      const u = d.displacement; // a skinDisplacement packet's vector (toPacket below)
      hasVec[k] = u ? 1 : 0;
      if (u) {
        V[3 * k] = u.x;
        V[3 * k + 1] = u.y;
        V[3 * k + 2] = u.z;
      }
      if (I[k] === 0 && v !== 0) act[na++] = k; // a node named twice is listed once
      I[k] = v;
      if (v > max) max = v;
      if (mark[k] !== epoch) {
        mark[k] = epoch;
        ch[nc++] = k;
      }
    }
    this.nActive = na;
    if (full) for (nc = 0; nc < this.n; nc++) ch[nc] = nc;
    this.nChanged = nc;
    const r = this.rest, nrm = this.normals;
    for (let c = 0; c < nc; c++) {
      const v = ch[c];
      if (hasVec[v] && I[v] > 0) { // the node's own vector
        this.x[v] = r[3 * v] + scale * V[3 * v];
        this.y[v] = r[3 * v + 1] + scale * V[3 * v + 1];
        this.z[v] = r[3 * v + 2] + scale * V[3 * v + 2];
        continue;
      }
      const s = I[v] * scale;
      this.x[v] = r[3 * v] - s * nrm[3 * v];
      this.y[v] = r[3 * v + 1] - s * nrm[3 * v + 1];
      this.z[v] = r[3 * v + 2] - s * nrm[3 * v + 2];
    }
    return max;
  }

  // The tangential part (shear) of each active node's vector, for the arrows: [k, tx, ty, tz] rows.
  shear() {
    const out = [], V = this.vec, nrm = this.normals;
    for (let a = 0; a < this.nActive; a++) {
      const k = this.active[a];
      if (!this.hasVec[k]) continue;
      const ux = V[3 * k], uy = V[3 * k + 1], uz = V[3 * k + 2];
      const dn = ux * nrm[3 * k] + uy * nrm[3 * k + 1] + uz * nrm[3 * k + 2];
      out.push([k, ux - dn * nrm[3 * k], uy - dn * nrm[3 * k + 1], uz - dn * nrm[3 * k + 2]]);
    }
    return out;
  }
}

// A skinDisplacement packet in the form Skin.apply takes: each node's norm as its intensity (the
// same, to 1 µm, as the frame's skinDeformedDetection packet) and its vector.
export function toPacket(displacement) {
  const nodes = (displacement.arrayOfDisplacedNodes || []).map((d) => {
    const u = d.displacement;
    return {deformedNodeID: d.nodeID, deformedNodeIntensity: Math.hypot(u.x, u.y, u.z), displacement: u};
  });
  return {timeStamp: displacement.timeStamp, numOfDeformedNodes: nodes.length, arrayOfDeformedNodes: nodes};
}
