// The skin drawn with three.js (vendored, docs/dependencies.md): one BufferGeometry whose
// position, normal and colour attributes are rewritten in place for the nodes a packet moved,
// and uploaded as those ranges only (addUpdateRange). A draw is then a few kB to the GPU and
// one render of ~1,400 triangles: a few ms in software WebGL, where plotly's restyle of the
// whole mesh took 200-270 ms (issue 18).

import * as THREE from "./vendor/three.module.min.js";
import {OrbitControls} from "./vendor/OrbitControls.js";

// intensity / cmax -> colour: the stops the twin has always used (pale at rest, red deep)
export const COLOUR_STOPS = [[0, "#dfe7ee"], [0.15, "#9ecae1"], [0.4, "#fdd049"], [0.7, "#f46d43"], [1, "#a50026"]];
const STOPS = COLOUR_STOPS.map(([t, hex]) => [t, ...[1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16) / 255)]);
// The camera looks from +x, -y and above (the side the demo scenes press; docs/twin.md).
export const EYE = [1.2, -1.2, 0.7];
const MAX_RANGES = 8; // more dirty runs than this: upload one span covering them

THREE.ColorManagement.enabled = false; // colours are used as given, no sRGB round trip

function colourOf(v, out, o) {
  const t = v <= 0 ? 0 : v >= 1 ? 1 : v;
  let s = 1;
  while (s < STOPS.length - 1 && STOPS[s][0] < t) s++;
  const [t0, r0, g0, b0] = STOPS[s - 1], [t1, r1, g1, b1] = STOPS[s];
  const f = t1 > t0 ? (t - t0) / (t1 - t0) : 0;
  out[o] = r0 + f * (r1 - r0);
  out[o + 1] = g0 + f * (g1 - g0);
  out[o + 2] = b0 + f * (b1 - b0);
}

export class SkinView {
  constructor(container, skin, {onChange = null} = {}) {
    this.container = container;
    this.skin = skin;
    const n = skin.n, m = skin.i.length;
    this.cmax = 1;
    this.dirty = new Uint8Array(n);
    this.list = new Int32Array(n);
    this.needsRender = true;
    // vertex -> incident triangles (CSR), to recompute the normals around moved nodes
    const deg = new Int32Array(n + 1);
    for (let t = 0; t < m; t++) for (const v of [skin.i[t], skin.j[t], skin.k[t]]) deg[v + 1]++;
    for (let v = 0; v < n; v++) deg[v + 1] += deg[v];
    const fill = deg.slice(0, n), tris = new Int32Array(3 * m);
    for (let t = 0; t < m; t++) for (const v of [skin.i[t], skin.j[t], skin.k[t]]) tris[fill[v]++] = t;
    this.adjStart = deg;
    this.adjTri = tris;

    const index = new Uint32Array(3 * m);
    for (let t = 0; t < m; t++) {
      index[3 * t] = skin.i[t];
      index[3 * t + 1] = skin.j[t];
      index[3 * t + 2] = skin.k[t];
    }
    const geo = (this.geometry = new THREE.BufferGeometry());
    this.pos = new THREE.BufferAttribute(new Float32Array(3 * n), 3).setUsage(THREE.DynamicDrawUsage);
    this.nrm = new THREE.BufferAttribute(new Float32Array(3 * n), 3).setUsage(THREE.DynamicDrawUsage);
    this.col = new THREE.BufferAttribute(new Float32Array(3 * n), 3).setUsage(THREE.DynamicDrawUsage);
    geo.setAttribute("position", this.pos);
    geo.setAttribute("normal", this.nrm);
    geo.setAttribute("color", this.col);
    geo.setIndex(new THREE.BufferAttribute(index, 1));
    const material = new THREE.MeshLambertMaterial({vertexColors: true, side: THREE.DoubleSide});
    this.mesh = new THREE.Mesh(geo, material);
    this.mesh.frustumCulled = false; // the bounding sphere would go stale as nodes move

    const scene = (this.scene = new THREE.Scene());
    scene.background = new THREE.Color("#ffffff");
    scene.add(this.mesh);
    // three.js lights are physical (Lambert divides by pi): these give plotly's old look
    scene.add(new THREE.AmbientLight(0xffffff, 0.6 * Math.PI));
    const ranges = skin.ranges();
    const lo = ranges.map((r) => r[0]), hi = ranges.map((r) => r[1]);
    const centre = new THREE.Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
    const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    this.addAxes(lo, hi);

    const camera = (this.camera = new THREE.PerspectiveCamera(35, 1, span / 100, span * 20));
    camera.up.set(0, 0, 1);
    const eye = new THREE.Vector3(...EYE).normalize();
    camera.position.copy(centre).addScaledVector(eye, 2.1 * span);
    camera.lookAt(centre);
    const light = new THREE.DirectionalLight(0xffffff, 0.6 * Math.PI);
    light.position.set(0.3, 0.5, 1); // camera space: from just above and right of the eye
    light.target.position.set(0, 0, -1);
    camera.add(light, light.target); // a head light: whatever side is looked at is lit
    scene.add(camera);

    const renderer = (this.renderer = new THREE.WebGLRenderer({antialias: false, powerPreference: "low-power"}));
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    renderer.setPixelRatio(Math.min(2, Math.max(1, window.devicePixelRatio || 1)));
    container.replaceChildren(renderer.domElement);
    this.controls = new OrbitControls(camera, renderer.domElement);
    this.controls.target.copy(centre);
    this.controls.update();
    this.controls.addEventListener("change", () => {
      this.needsRender = true;
      if (onChange) onChange();
    });
    this.span = span;
    this.addArrows(n);
    this.markers = [];
    this.markerGeometry = new THREE.OctahedronGeometry(Math.max(span / 70, 1));
    this.markerSize = Math.max(span / 70, 1); // the diamond's radius at full force
    this.fmax = 0; // the largest contact force drawn lately, N (decays): the scale of every marker
    this.labels = new Map(); // contact id -> its label's texture, while shown
    this.marks = []; // what the last setContacts drew: [{id, force, scale, colour}] (for the tests)
    this.resize = new ResizeObserver(() => this.fit());
    this.resize.observe(container);
    this.fit();
    this.update(true);
  }

  addAxes(lo, hi) {
    // the fixed ranges' box (plotly's scene box, faint) and x/y/z from its low corner
    const box = new THREE.Box3(new THREE.Vector3(...lo), new THREE.Vector3(...hi));
    const helper = new THREE.Box3Helper(box, new THREE.Color("#dde2e8"));
    this.scene.add(helper);
    const colours = ["#d62728", "#2ca02c", "#1f77b4"];
    for (let d = 0; d < 3; d++) {
      const end = [...lo];
      end[d] = hi[d];
      const g = new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(...lo), new THREE.Vector3(...end)]);
      this.scene.add(new THREE.Line(g, new THREE.LineBasicMaterial({color: colours[d]})));
    }
  }

  fit() {
    const w = Math.max(1, this.container.clientWidth), h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.needsRender = true;
  }

  setCmax(cmax) {
    if (cmax === this.cmax) return;
    this.cmax = cmax;
    this.update(true); // every colour depends on it
  }

  // Copy the skin's moved nodes (skin.changed, or all with ``full``) into the attributes, with
  // the normals around them, and mark just those ranges for upload.
  update(full = false) {
    const skin = this.skin, n = skin.n, dirty = this.dirty, list = this.list;
    const P = this.pos.array, C = this.col.array, inv = 1 / this.cmax;
    let nl = 0;
    const moved = full ? n : skin.nChanged;
    for (let c = 0; c < moved; c++) {
      const v = full ? c : skin.changed[c];
      P[3 * v] = skin.x[v];
      P[3 * v + 1] = skin.y[v];
      P[3 * v + 2] = skin.z[v];
      colourOf(skin.intensity[v] * inv, C, 3 * v);
      // every vertex sharing a triangle with a moved one gets a new normal
      for (let a = this.adjStart[v]; a < this.adjStart[v + 1]; a++) {
        const t = this.adjTri[a];
        for (const u of [skin.i[t], skin.j[t], skin.k[t]]) {
          if (!dirty[u]) {
            dirty[u] = 1;
            list[nl++] = u;
          }
        }
      }
    }
    if (nl === 0) return 0;
    const sorted = list.subarray(0, nl).sort();
    for (let c = 0; c < nl; c++) {
      this.normal(sorted[c]);
      dirty[sorted[c]] = 0;
    }
    this.upload(sorted, moved === n);
    this.needsRender = true;
    return nl;
  }

  normal(v) {
    const s = this.skin, P = this.pos.array, N = this.nrm.array;
    let nx = 0, ny = 0, nz = 0;
    for (let a = this.adjStart[v]; a < this.adjStart[v + 1]; a++) {
      const t = this.adjTri[a], A = 3 * s.i[t], B = 3 * s.j[t], C = 3 * s.k[t];
      const ux = P[B] - P[A], uy = P[B + 1] - P[A + 1], uz = P[B + 2] - P[A + 2];
      const vx = P[C] - P[A], vy = P[C + 1] - P[A + 1], vz = P[C + 2] - P[A + 2];
      nx += uy * vz - uz * vy;
      ny += uz * vx - ux * vz;
      nz += ux * vy - uy * vx;
    }
    const l = Math.hypot(nx, ny, nz) || 1;
    N[3 * v] = nx / l;
    N[3 * v + 1] = ny / l;
    N[3 * v + 2] = nz / l;
  }

  // Sorted dirty vertices -> a few [start, end) runs (gaps under 16 vertices merged).
  upload(sorted, all) {
    const runs = [];
    if (all) runs.push([0, this.skin.n]);
    else {
      let start = sorted[0], end = sorted[0] + 1;
      for (let c = 1; c < sorted.length; c++) {
        if (sorted[c] - end < 16) end = sorted[c] + 1;
        else {
          runs.push([start, end]);
          start = sorted[c];
          end = start + 1;
        }
      }
      runs.push([start, end]);
      if (runs.length > MAX_RANGES) runs.splice(0, runs.length, [runs[0][0], runs[runs.length - 1][1]]);
    }
    for (const attr of [this.pos, this.nrm, this.col]) {
      attr.clearUpdateRanges();
      for (const [a, b] of runs) attr.addUpdateRange(3 * a, 3 * (b - a));
      attr.needsUpdate = true;
    }
    this.uploaded = runs.reduce((k, [a, b]) => k + b - a, 0); // vertices sent by the last update
  }

  // One diamond per contact at its location, sized and coloured by its force against the largest
  // force drawn lately (a 0.5 N side lobe is a speck beside a 45 N press; square root: the
  // diamond's area follows the force; the memory fades by 1 % an update, so a light touch after a
  // hard one is drawn full size again within seconds), with the contact's id above it, so two
  // fingers read as two and keep their labels while they move.
  // ``contacts``: [{x, y, z, force (N), id (or null)}].
  setContacts(contacts) {
    this.fmax *= 0.99;
    for (const c of contacts) this.fmax = Math.max(this.fmax, c.force);
    while (this.markers.length < contacts.length) {
      const m = new THREE.Mesh(this.markerGeometry, new THREE.MeshBasicMaterial({color: 0x111111}));
      const label = new THREE.Sprite(new THREE.SpriteMaterial({depthTest: false, transparent: true}));
      label.renderOrder = 1;
      this.scene.add(m, label);
      this.markers.push({m, label});
    }
    const shown = new Set();
    this.marks = contacts.map((c, k) => {
      const rel = this.fmax > 0 ? Math.min(1, c.force / this.fmax) : 1;
      const scale = 0.35 + 0.65 * Math.sqrt(rel);
      const {m, label} = this.markers[k];
      m.position.set(c.x, c.y, c.z);
      m.scale.setScalar(scale);
      const rgb = [0, 0, 0];
      colourOf(0.25 + 0.75 * rel, rgb, 0);
      m.material.color.setRGB(rgb[0], rgb[1], rgb[2]);
      label.visible = c.id != null;
      if (label.visible) {
        shown.add(c.id);
        label.material.map = this.label(c.id);
        label.material.needsUpdate = true;
        const h = 2.2 * this.markerSize;
        label.scale.set(2 * h, h, 1);
        label.position.set(c.x, c.y, c.z + 1.6 * h);
      }
      return {id: c.id, force: c.force, scale, colour: rgb.map((v) => Math.round(v * 255))};
    });
    this.markers.forEach(({m, label}, k) => {
      m.visible = k < contacts.length;
      if (!m.visible) label.visible = false;
    });
    for (const [id, texture] of this.labels) if (!shown.has(id)) {
      texture.dispose();
      this.labels.delete(id);
    }
    this.needsRender = true;
  }

  // "#<id>" on a transparent canvas, made once per contact id while it is shown
  label(id) {
    let texture = this.labels.get(id);
    if (!texture) {
      const canvas = document.createElement("canvas");
      canvas.width = 128;
      canvas.height = 64;
      const g = canvas.getContext("2d");
      g.font = "bold 44px sans-serif";
      g.textAlign = "center";
      g.textBaseline = "middle";
      g.lineWidth = 8;
      g.strokeStyle = "#ffffff";
      g.strokeText(`#${id}`, 64, 34);
      g.fillStyle = "#111111";
      g.fillText(`#${id}`, 64, 34);
      texture = new THREE.CanvasTexture(canvas);
      this.labels.set(id, texture);
    }
    return texture;
  }

  // Shear arrows (one line per displaced node, its vector's tangential part) and contact forces
  // (an arrow per contact): layers of their own over the skin, rewritten whole at each draw.
  addArrows(n) {
    const g = (this.shearGeometry = new THREE.BufferGeometry());
    this.shearPos = new THREE.BufferAttribute(new Float32Array(6 * Math.max(n, 1)), 3)
      .setUsage(THREE.DynamicDrawUsage);
    g.setAttribute("position", this.shearPos);
    g.setDrawRange(0, 0);
    this.shearLines = new THREE.LineSegments(g, new THREE.LineBasicMaterial({color: 0x1f4e9a}));
    this.shearLines.frustumCulled = false;
    this.scene.add(this.shearLines);
    this.forceArrows = [];
    this.nShear = 0;
    this.nForces = 0;
  }

  // ``rows``: [vertex, tx, ty, tz] (Skin.shear); each arrow starts at the vertex as drawn and is
  // ``gain`` times the shear long. Returns the longest shear (mm).
  setShear(rows, gain) {
    const P = this.pos.array, L = this.shearPos.array;
    let m = 0, longest = 0;
    for (const [v, tx, ty, tz] of rows) {
      const len = Math.hypot(tx, ty, tz);
      if (!(len > 0) || gain <= 0) continue;
      longest = Math.max(longest, len);
      L[6 * m] = P[3 * v];
      L[6 * m + 1] = P[3 * v + 1];
      L[6 * m + 2] = P[3 * v + 2];
      L[6 * m + 3] = P[3 * v] + gain * tx;
      L[6 * m + 4] = P[3 * v + 1] + gain * ty;
      L[6 * m + 5] = P[3 * v + 2] + gain * tz;
      m++;
    }
    this.nShear = m;
    this.shearGeometry.setDrawRange(0, 2 * m);
    this.shearPos.clearUpdateRanges();
    this.shearPos.addUpdateRange(0, 6 * m);
    this.shearPos.needsUpdate = true;
    this.needsRender = true;
    return longest;
  }

  // One arrow per contact: from its location along its force (on the skin), ``mmPerN`` mm per newton.
  setForces(locations, forces, mmPerN) {
    const k = Math.min(locations.length, forces.length);
    while (this.forceArrows.length < k) {
      const a = new THREE.ArrowHelper(new THREE.Vector3(0, 0, -1), new THREE.Vector3(), 1, 0xb5179e);
      this.scene.add(a);
      this.forceArrows.push(a);
    }
    const dir = new THREE.Vector3();
    this.forceArrows.forEach((a, i) => {
      const f = i < k ? forces[i] : null;
      const len = f ? Math.hypot(f.x, f.y, f.z) * mmPerN : 0;
      a.visible = len > 0;
      if (!a.visible) return;
      const p = locations[i];
      dir.set(f.x, f.y, f.z).normalize();
      a.position.set(p.x - dir.x * len, p.y - dir.y * len, p.z - dir.z * len); // the tip on the contact
      a.setDirection(dir);
      a.setLength(len, Math.min(len * 0.3, this.span / 25), Math.min(len * 0.15, this.span / 50));
    });
    this.nForces = this.forceArrows.filter((a) => a.visible).length;
    this.needsRender = true;
  }

  render() {
    this.renderer.render(this.scene, this.camera);
    this.needsRender = false;
  }

  dispose() {
    for (const texture of this.labels.values()) texture.dispose();
    this.resize.disconnect();
    this.controls.dispose();
    this.geometry.dispose();
    this.renderer.dispose();
    this.renderer.forceContextLoss(); // a replay and back builds a new view: free the old context now
  }
}
