// The device page: the skin as a 3D mesh from its TD, deformed live by skinDeformedDetection.
//
// Events arrive at up to the device's frame rate (120 Hz and more); the page draws at the
// display's rate. Since every packet is the complete deformed set, only the newest one
// matters: each SSE message just replaces ``pending`` and one requestAnimationFrame loop
// draws it when the previous draw is done. Nothing queues up, whatever the event rate.

import {Skin} from "./skin.js";
import {ReplayControl} from "./replay.js";
import {discover, getJSON, hubKeyOf, now, observeProperty, readProperty, subscribeEvents} from "./wot.js";

const WINDOW = 120; // delay samples kept for the median and p95

const state = (window.twin = {
  page: "device", ready: false, thing: null, title: null, mode: "live", nodes: 0, cells: 0,
  packets: 0, frames: 0, last: null, applied: null, drawn: null, onsets: [], seqs: [], stream: null, reconnects: 0,
  action: null, actions: [], contacts: 0, delays: {net: [], draw: [], e2e: []}, errors: [], cmax: 1,
  freeze: false, // hold the picture (events are still received and counted)
});

const $ = (id) => document.getElementById(id);
const plot = $("skin");
let view = null; // the Thing shown: {td, skin, streams, contactStream}
let pending = null; // newest packet not drawn yet
let pendingContacts = null;
let busy = false;
let scale = 1;

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
  skin.apply({arrayOfDeformedNodes: []}, scale);
  await drawMesh(skin);
  const v = (view = {td, skin, streams: [], contactStream: null, url: tdUrl});
  if (contacts) setContacts(contacts);
  v.streams = subscribeEvents(td, ["skinDeformedDetection", "actionDetection"], (name, data, id) => {
    state.seqs.push(Number(id)); // every event id of the stream, to check resumes lose nothing
    if (state.seqs.length > 50000) state.seqs.splice(0, 25000);
    if (name === "skinDeformedDetection") onPacket(data, id);
    else onAction(data);
  }, {after, onState: streamState});
  v.contactStream = observeProperty(td, "contactInformation", (value) => {
    pendingContacts = value;
  });
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
  pending = pendingContacts = null;
}

function close() {
  detach();
  view = null;
}

async function drawMesh(skin) {
  const mesh = {
    type: "mesh3d", x: Array.from(skin.x), y: Array.from(skin.y), z: Array.from(skin.z),
    i: Array.from(skin.i), j: Array.from(skin.j), k: Array.from(skin.k),
    intensity: Array.from(skin.intensity), intensitymode: "vertex", cmin: 0, cmax: state.cmax,
    colorscale: [[0, "#dfe7ee"], [0.15, "#9ecae1"], [0.4, "#fdd049"], [0.7, "#f46d43"], [1, "#a50026"]],
    colorbar: {title: {text: "‖D‖ mm"}, thickness: 12, len: 0.6},
    lighting: {ambient: 0.75, diffuse: 0.45, specular: 0.1, roughness: 0.7, fresnel: 0.1},
    hovertemplate: "node %{customdata}<br>%{intensity:.3f} mm<extra></extra>",
    customdata: Array.from({length: skin.n}, (_, k) => k), name: "skin",
  };
  const contacts = {
    type: "scatter3d", mode: "markers", x: [], y: [], z: [], text: [], name: "contacts",
    marker: {size: 7, color: "#111", symbol: "diamond"}, hovertemplate: "contact<br>%{text}<extra></extra>",
  };
  const ranges = skin.ranges();
  const span = Math.max(...ranges.map(([a, b]) => b - a));
  const axis = (t, r) => ({title: {text: t}, range: r, autorange: false, showbackground: false,
    gridcolor: "#e3e7eb", zeroline: false});
  const layout = {
    margin: {l: 0, r: 0, t: 0, b: 0}, showlegend: false, paper_bgcolor: "#fff", uirevision: "keep",
    scene: {
      xaxis: axis("x mm", ranges[0]), yaxis: axis("y mm", ranges[1]), zaxis: axis("z mm", ranges[2]),
      aspectmode: "manual", // true proportions (fixed ranges, so "data" would not apply)
      aspectratio: {x: (ranges[0][1] - ranges[0][0]) / span, y: (ranges[1][1] - ranges[1][0]) / span,
        z: (ranges[2][1] - ranges[2][0]) / span},
      camera: {eye: {x: 1.2, y: -1.2, z: 0.7}},
    },
  };
  // plotly renders 3D at twice the screen's resolution by default: four times the pixels to
  // fill at every update for nothing on a standard display
  const plotGlPixelRatio = Math.min(2, Math.max(1, window.devicePixelRatio || 1));
  await Plotly.react(plot, [mesh, contacts], layout, {responsive: true, displaylogo: false, plotGlPixelRatio});
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

function setContacts(value) {
  state.contacts = value.numOfContacts || 0;
  $("contacts").textContent = state.contacts;
  const loc = value.contactLocations || [], f = value.contactForces || [];
  const text = f.map((v) => `${Math.hypot(v.x, v.y, v.z).toFixed(2)} N`);
  Plotly.restyle(plot, {x: [loc.map((p) => p.x)], y: [loc.map((p) => p.y)], z: [loc.map((p) => p.z)], text: [text]},
    [1]);
}

function streamState(s, stream) {
  state.streamState = s;
  state.reconnects = view ? view.streams.reduce((n, x) => n + x.reconnects, 0) : stream.reconnects;
  const el = $("stream");
  el.textContent = s;
  el.className = `badge state-${s}`;
  $("reconnects").textContent = state.reconnects;
}

function sample(kind, ms) {
  const a = state.delays[kind];
  a.push(ms);
  if (a.length > WINDOW) a.shift();
}

// --- drawing: at most one mesh update per display frame --------------------------------------

function frame() {
  requestAnimationFrame(frame);
  if (!view || busy || state.freeze) return;
  if (pendingContacts) {
    setContacts(pendingContacts);
    pendingContacts = null;
  }
  if (!pending) return;
  const job = pending;
  pending = null;
  busy = true;
  const skin = view.skin;
  skin.apply(job.packet, scale);
  if (job.max > state.cmax) state.cmax = Math.ceil(job.max * 2) / 2;
  state.applied = {seq: job.seq, max: job.max, at: now()};
  for (const o of state.onsets) if (o.applied === null && o.seq <= job.seq) o.applied = state.applied.at;
  Plotly.restyle(plot, {
    x: [Array.from(skin.x)], y: [Array.from(skin.y)], z: [Array.from(skin.z)],
    intensity: [Array.from(skin.intensity)], cmax: [state.cmax],
  }, [0]).then(() => requestAnimationFrame(() => {
    const t = now();
    busy = false;
    state.frames++;
    state.drawn = {seq: job.seq, max: job.max, at: t};
    if (!job.redraw) {
      sample("draw", t - job.at);
      if (state.mode === "live") sample("e2e", t - job.stamp);
    }
    for (const o of state.onsets) if (o.drawn === null && o.seq <= job.seq) o.drawn = t;
    $("deformed").textContent = skin.intensity.reduce((n, v) => n + (v > 0), 0);
    $("peak").textContent = `${job.max.toFixed(3)} mm`;
  }), (e) => {
    busy = false;
    showError(e);
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
  $("freeze").onchange = (e) => (state.freeze = e.target.checked);
  $("exaggerate").onchange = (e) => {
    scale = Number(e.target.value);
    if (view && state.last) pending = pending || {packet: lastPacket(), seq: state.last.seq, at: now(),
      max: state.last.max, stamp: state.last.stamp, redraw: true};
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
  // redraw the last packet at a new scale: the skin keeps its intensities
  const skin = view.skin, nodes = [];
  for (const [id, k] of skin.index) if (skin.intensity[k] > 0) nodes.push({deformedNodeID: id,
    deformedNodeIntensity: skin.intensity[k]});
  return {numOfDeformedNodes: nodes.length, arrayOfDeformedNodes: nodes};
}

main().catch(showError);
