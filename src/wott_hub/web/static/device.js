// The device page: the skin as a 3D mesh from its TD, deformed live by skinDisplacement (each
// node moved by its vector, shear drawn as arrows) or, from a Thing that does not declare it, by
// skinDeformedDetection (along the inward normal); contact forces as arrows, and for a camera
// device the live raw image (its rawImage stream form: an <img> the browser keeps replacing).
//
// Events arrive at up to the device's frame rate (120 Hz and more); the page draws at most once
// per display frame. Every packet is the complete deformed set, so only the newest one matters:
// a message replaces ``pending`` and is drawn at once if nothing was drawn in this display frame
// yet, else by the next requestAnimationFrame, together with any packet after it (coalesced,
// never lost: the counters in ``window.__twinStats`` account for every packet). A draw moves
// only the nodes the packet changed (render3d.js), so it costs a few ms and messages never wait
// behind it (plotly's whole-mesh restyle took 200-270 ms; issue 18).

import {Skin, toPacket} from "./skin.js";
import {COLOUR_STOPS, SkinView} from "./render3d.js";
import {ReplayControl} from "./replay.js";
import {discover, getJSON, href, hubKeyOf, now, observeProperty, readProperty, subscribeEvents, withToken} from "./wot.js";

const WINDOW = 120; // delay samples kept for the panel's median and p95
const LOG = 100000; // delay samples kept for the benchmark (window.__twinStats)

const state = (window.twin = {
  // what the browser tests read of the geometry drawn: a vertex's vector, rest and drawn position, the scale
  skinState: () => {
    const s = view.skin, P = view3d.pos.array, at = (a, k) => [a[3 * k], a[3 * k + 1], a[3 * k + 2]];
    return {scale, vec: (k) => (s.hasVec[k] ? at(s.vec, k) : null), rest: (k) => at(s.rest, k), pos: (k) => at(P, k)};
  },
  page: "device", ready: false, thing: null, title: null, mode: "live", nodes: 0, cells: 0,
  packets: 0, frames: 0, last: null, applied: null, drawn: null, onsets: [], seqs: [], stream: null, reconnects: 0,
  action: null, actions: [], contacts: 0, contactIds: [], marks: [], delays: {net: [], draw: [], e2e: []},
  errors: [], cmax: 1,
  freeze: false, // hold the picture (events are still received and counted)
});

const $ = (id) => document.getElementById(id);
const plot = $("skin");
let view = null; // the Thing shown: {td, skin, streams, contactStream}
let view3d = null; // its SkinView
let pending = null; // newest packet not drawn yet
let pendingContacts = null;
let drewInFrame = false; // a draw already happened in this display frame
let scale = 1;
let arrowGain = 5; // shear arrows: this many times the shear (the page's "arrows" control; 0: off)
const MM_PER_N = 10; // contact force arrows: length per newton
let pendingForces = null; // the last contactInformation value not drawn as arrows yet

// What the benchmark (wott-hub bench twin) and the tests read: every delay sample since reset(),
// and the packet accounting: packets = coalesced (drawn, or replaced by a newer packet that was
// drawn) + waiting (received since the last draw) + dropped (pending when the page left a view).
const log = {hubToPage: [], pageToScreen: [], endToEnd: [], drawMs: [], packets: 0, draws: 0, coalesced: 0,
  waiting: 0, dropped: 0, uploaded: 0};
window.__twinStats = {
  reset() {
    for (const k of ["hubToPage", "pageToScreen", "endToEnd", "drawMs"]) log[k] = [];
    log.packets = log.draws = log.coalesced = log.uploaded = 0;
    log.waiting = log.dropped = 0;
  },
  snapshot() {
    return {thing: state.thing, mode: state.mode, ...log};
  },
};

function showError(e) {
  const msg = String(e && e.message ? e.message : e);
  state.errors.push(msg);
  $("error").textContent = msg;
  $("error").hidden = false;
}

// --- showing a Thing --------------------------------------------------------------------

async function show(tdUrl, {after = null, mode = "live"} = {}) {
  close();
  state.ready = false;
  const td = await getJSON(tdUrl, "application/td+json");
  const [nodes, cells, contacts] = await Promise.all([
    readProperty(td, "skinNodes"), readProperty(td, "skinCells"),
    readProperty(td, "contactInformation").catch(() => null),
  ]);
  const skin = new Skin(nodes, cells);
  Object.assign(state, {
    thing: td.id, title: td.title, mode, nodes: skin.n, cells: skin.cells, packets: 0, frames: 0, last: null,
    applied: null, drawn: null, onsets: [], seqs: [], reconnects: 0,
    cmax: Math.max(1, 10 * (td["tac:epsilon"] || 0.1)),
  });
  state.delays = {net: [], draw: [], e2e: []};
  $("title").textContent = td.title;
  $("family").textContent = td["tac:family"] || "";
  $("mode").textContent = mode;
  $("mode").className = `badge state-${mode}`;
  $("mesh").textContent = `${skin.n} nodes, ${skin.cells} cells`;
  document.title = `wott-hub · ${td.title}`;
  drawMesh(skin);
  const vectors = !!(td.events || {}).skinDisplacement; // the geometry from the vectors
  state.vectors = vectors;
  // a skin whose nodes measure no displacement (tac:nodeSignal: a field in µT, counts) is coloured, not dented
  const unit = intensityUnit(td);
  state.dents = unit === "mm";
  const label = document.querySelector("#colourbar .cb-title");
  if (label) label.textContent = state.dents ? "‖D‖ mm" : `${td["tac:nodeSignal"] || "change"} ${unit}`;
  const v = (view = {td, skin, streams: [], contactStream: null, url: tdUrl, vectors});
  if (contacts) setContacts(contacts);
  if (contacts) pendingForces = contacts;
  // every event the TD declares (actionDetails too), though only a few are drawn
  v.streams = subscribeEvents(td, Object.keys(td.events || {}), (name, data, id) => {
    state.seqs.push(Number(id)); // every event id of the stream, to check resumes lose nothing
    if (state.seqs.length > 50000) state.seqs.splice(0, 25000);
    if (name === (vectors ? "skinDisplacement" : "skinDeformedDetection")) {
      onPacket(vectors ? toPacket(data) : data, id);
    } else if (name === "actionDetection") onAction(data);
  }, {after, onState: streamState});
  v.contactStream = observeProperty(td, "contactInformation", (value) => {
    pendingContacts = value;
    pendingForces = value;
  });
  showRawImage(td);
  state.stream = v.streams[0].url;
  state.ready = true;
  return td;
}

// Stop listening; the mesh stays as it was drawn last (a paused replay).
function detach() {
  if (!view) return;
  for (const s of view.streams) s.close();
  if (view.contactStream) view.contactStream.close();
  view.streams = [];
  view.contactStream = null;
  pending = pendingContacts = pendingForces = null;
  const img = $("raw-image");
  if (img) img.removeAttribute("src"); // ends the image stream
  log.dropped += log.waiting; // packets of a view left before they were drawn
  log.waiting = 0;
}

function close() {
  detach();
  view = null;
}

function drawMesh(skin) {
  if (view3d) view3d.dispose();
  view3d = new SkinView(plot, skin, {onChange: () => requestDraw()});
  view3d.setCmax(state.cmax);
  colourBar();
  view3d.render();
  // what the tests check of the mesh on screen (plotly's trace used to answer this)
  plot.data = [{
    type: "mesh", renderer: "three.js",
    get x() { return view3d.pos.array.filter((_, k) => k % 3 === 0); },
    get y() { return view3d.pos.array.filter((_, k) => k % 3 === 1); },
    get z() { return view3d.pos.array.filter((_, k) => k % 3 === 2); },
    get rest() { return Array.from(skin.rest); },
    get i() { return skin.i; },
    get intensity() { return skin.intensity; },
  }];
}

function intensityUnit(td) {
  const skin = ((td.events || {}).skinDeformedDetection || {}).data || {};
  const node = ((skin.properties || {}).arrayOfDeformedNodes || {}).items || {};
  return ((node.properties || {}).deformedNodeIntensity || {}).unit || "mm";
}

function colourBar() {
  const bar = $("colourbar");
  if (!bar) return;
  bar.querySelector(".ramp").style.background =
    `linear-gradient(to top, ${COLOUR_STOPS.map(([t, c]) => `${c} ${t * 100}%`).join(", ")})`;
  $("cb-max").textContent = state.cmax.toFixed(1);
  $("cb-mid").textContent = (state.cmax / 2).toFixed(1);
}

// --- events -------------------------------------------------------------------------------

function onPacket(packet, id) {
  const t = now();
  let max = 0;
  for (const d of packet.arrayOfDeformedNodes || []) max = Math.max(max, d.deformedNodeIntensity);
  const prev = state.last;
  const stampMs = packet.timeStamp / 1e6;
  state.packets++;
  state.last = {seq: Number(id), n: packet.numOfDeformedNodes, max, stamp: stampMs, at: t};
  if (max > 0 && (!prev || prev.max === 0)) {
    state.onsets.push({seq: Number(id), stamp: stampMs, received: t, applied: null, drawn: null});
    if (state.onsets.length > 50) state.onsets.shift();
  }
  if (state.mode === "live") sample("net", t - stampMs);
  pending = {packet, seq: Number(id), at: t, max, stamp: stampMs};
  log.packets++;
  log.waiting++;
  if (!drewInFrame) draw(); // the first packet of a display frame is drawn at once
}

// A contact, a camera move or a resize: redrawn by the next animation frame.
function requestDraw() {
  if (view3d) view3d.needsRender = true;
}

function onAction(action) {
  state.action = action;
  state.actions.unshift({action, at: now()});
  state.actions.length = Math.min(state.actions.length, 8);
  $("action").textContent = action;
  $("actions").replaceChildren(...state.actions.slice(1, 6).map((a) => {
    const li = document.createElement("li");
    li.textContent = a.action;
    return li;
  }));
}

// contactInformation: each contact's location, force and (from hubs with tracking, issue 31) its id
function setContacts(value) {
  state.contacts = value.numOfContacts || 0;
  $("contacts").textContent = state.contacts;
  const loc = value.contactLocations || [], f = value.contactForces || [], ids = value.contactIds || [];
  const contacts = loc.map((p, k) => ({x: p.x, y: p.y, z: p.z, id: ids[k] ?? null,
    force: f[k] ? Math.hypot(f[k].x, f[k].y, f[k].z) : 0}));
  state.contactIds = contacts.map((c) => c.id);
  $("contacts").title = contacts.map((c) => `${c.id == null ? "" : `#${c.id}: `}${c.force.toFixed(2)} N`).join(", ");
  if (view3d) {
    view3d.setContacts(contacts);
    state.marks = view3d.marks;
  }
}

function streamState(s, stream) {
  state.streamState = s;
  state.reconnects = view ? view.streams.reduce((n, x) => n + x.reconnects, 0) : stream.reconnects;
  const el = $("stream");
  el.textContent = s;
  el.className = `badge state-${s}`;
  $("reconnects").textContent = state.reconnects;
}

const LOGGED = {net: "hubToPage", draw: "pageToScreen", e2e: "endToEnd"};

function sample(kind, ms) {
  const a = state.delays[kind];
  a.push(ms);
  if (a.length > WINDOW) a.shift();
  const all = log[LOGGED[kind]];
  if (all.length < LOG) all.push(ms);
}

// --- drawing: at most one mesh update per display frame --------------------------------------

function frame() {
  requestAnimationFrame(frame);
  drewInFrame = false;
  if (!view) return;
  if (!state.freeze) {
    if (pendingContacts) {
      setContacts(pendingContacts);
      pendingContacts = null;
    }
    if (pending) draw();
    if (pendingForces && view3d) {
      view3d.setForces(pendingForces.contactLocations || [], pendingForces.contactForces || [], MM_PER_N);
      state.forces = view3d.nForces;
      pendingForces = null;
    }
  }
  // a camera move, a resize or contacts: also while the picture is held
  if (!drewInFrame && view3d && view3d.needsRender) {
    view3d.render();
    drewInFrame = true;
  }
}

// Apply the newest packet to the skin (the nodes it changes), upload those, render; the frame
// that shows it is the next animation frame, where the delays are taken.
function draw() {
  if (!view || !view3d || state.freeze || !pending) return;
  const job = pending;
  pending = null;
  const t0 = now();
  const skin = view.skin;
  skin.apply(job.packet, state.dents === false ? 0 : scale, !!job.redraw);
  state.applied = {seq: job.seq, max: job.max, at: t0};
  for (const o of state.onsets) if (o.applied === null && o.seq <= job.seq) o.applied = t0;
  if (job.max > state.cmax) {
    state.cmax = Math.ceil(job.max * 2) / 2;
    view3d.setCmax(state.cmax);
    colourBar();
  }
  view3d.update(!!job.redraw);
  if (view.vectors) {
    const longest = view3d.setShear(skin.shear(), scale * arrowGain);
    state.shear = {n: view3d.nShear, max: longest};
  }
  view3d.render();
  drewInFrame = true;
  log.draws++;
  log.coalesced += log.waiting;
  log.waiting = 0;
  log.uploaded += view3d.uploaded || 0;
  if (log.drawMs.length < LOG) log.drawMs.push(now() - t0);
  requestAnimationFrame(() => {
    const t = now();
    state.frames++;
    state.drawn = {seq: job.seq, max: job.max, at: t};
    if (!job.redraw) {
      sample("draw", t - job.at);
      if (state.mode === "live") sample("e2e", t - job.stamp);
    }
    for (const o of state.onsets) if (o.drawn === null && o.seq <= job.seq) o.drawn = t;
    $("deformed").textContent = skin.nActive;
    $("peak").textContent = `${job.max.toFixed(3)} mm`;
  });
}

function stats(a) {
  if (!a.length) return null;
  const s = [...a].sort((x, y) => x - y);
  return {last: a[a.length - 1], p50: s[Math.floor(s.length / 2)], p95: s[Math.min(s.length - 1,
    Math.floor(s.length * 0.95))]};
}

function panels() {
  for (const kind of ["net", "draw", "e2e"]) {
    const st = stats(state.delays[kind]);
    for (const k of ["last", "p50", "p95"]) $(`d-${kind}-${k}`).textContent = st ? st[k].toFixed(1) : "–";
  }
  $("delay-note").textContent = state.mode === "live"
    ? "Hub and browser clocks are compared: exact on one machine."
    : "Replayed packets keep their recorded timeStamp: only page → screen is measured.";
  $("packets").textContent = state.packets;
  $("frames").textContent = state.frames;
  $("last-id").textContent = state.last ? state.last.seq : "–";
}

// --- start ----------------------------------------------------------------------------------

async function main() {
  const tdUrl = new URLSearchParams(location.search).get("td");
  if (!tdUrl) throw new Error("no Thing given: open this page from the fleet page (?td=<TD URL>)");
  $("freeze").onchange = (e) => {
    state.freeze = e.target.checked;
    if (!state.freeze) requestDraw();
  };
  const redraw = () => {
    if (view && state.last) pending = pending || {packet: lastPacket(), seq: state.last.seq, at: now(),
      max: state.last.max, stamp: state.last.stamp, redraw: true};
  };
  $("exaggerate").onchange = (e) => {
    scale = Number(e.target.value);
    redraw();
  };
  $("arrows").onchange = (e) => {
    arrowGain = Number(e.target.value);
    redraw();
  };
  const td = await show(tdUrl);
  requestAnimationFrame(frame);
  setInterval(panels, 250);
  // the hub Thing offers replay; its device id for this TD comes from its ``devices`` property
  const {hub} = await discover();
  if (!hub || !(hub.td.actions || {}).replay) {
    $("replay-panel").hidden = true;
    return;
  }
  const key = hubKeyOf(td, await readProperty(hub.td, "devices"));
  state.device = key;
  new ReplayControl(hub.td, key, {
    show: (url, after) => show(url, {after, mode: "replay"}),
    live: () => show(tdUrl),
    detach,
    lastStamp: () => (state.last ? state.last.stamp : null),
    setMode: (m) => {
      state.mode = m;
      $("mode").textContent = m;
      $("mode").className = `badge state-${m}`;
    },
  });
}

function lastPacket() {
  // redraw the last packet at a new scale: the skin keeps its intensities (and vectors)
  const skin = view.skin, nodes = [];
  for (const [id, k] of skin.index) {
    if (!(skin.intensity[k] > 0)) continue;
    const node = {deformedNodeID: id, deformedNodeIntensity: skin.intensity[k]};
    if (skin.hasVec[k]) node.displacement = {x: skin.vec[3 * k], y: skin.vec[3 * k + 1], z: skin.vec[3 * k + 2]};
    nodes.push(node);
  }
  return {numOfDeformedNodes: nodes.length, arrayOfDeformedNodes: nodes};
}

// A camera device: its live image, the rawImage property's stream form (multipart/x-mixed-replace
// JPEG parts at maxRate) as an <img> source; a select when it has several cameras.
const RAW_RATE = 10;

function showRawImage(td) {
  const panel = $("raw-panel"), img = $("raw-image"), select = $("camera");
  const aff = (td.properties || {}).rawImage;
  const form = aff && (aff.forms || []).find((f) => (Array.isArray(f.op) ? f.op : [f.op]).includes("observeproperty")
    && String(f.contentType || "").startsWith("multipart/x-mixed-replace"));
  state.raw = null;
  if (!panel) return;
  panel.hidden = !form;
  if (!form) return;
  const cameras = ((aff.uriVariables || {}).camera || {}).enum || [];
  select.replaceChildren(...cameras.map((c) => Object.assign(document.createElement("option"), {value: c, textContent: c})));
  select.hidden = cameras.length < 2;
  const start = () => {
    const u = new URL(href(td, form));
    if (select.value) u.searchParams.set("camera", select.value);
    u.searchParams.set("maxRate", String(RAW_RATE));
    img.src = withToken(u.href);
    state.raw = {camera: select.value, src: u.href};
  };
  select.onchange = start;
  start();
}

main().catch(showError);
