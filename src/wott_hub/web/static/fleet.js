// The fleet page: every tactile Thing in the hub's directory, with its health, event rate and
// last action. Health and counters come from the hub Thing (its TD, its forms); the last
// action from each device's actionDetection event.

import {
  discover, hubKeyOf, now, observeProperty, readProperty, SseStream, subscribeEvent,
} from "./wot.js";

const state = (window.twin = {
  page: "fleet", ready: false, source: null, hub: null, hubState: null, devices: {}, errors: [],
  loads: 0,
});
const subs = new Map(); // TD id -> subscription to actionDetection
let hub = null; // {td, url}
let hubDevices = [];
let health = null;
let healthAt = 0; // when ``health`` was read: uptime goes on from there
let lastCounters = null;
let renderQueued = false;
let reloadTimer = null;

const $ = (id) => document.getElementById(id);

function showError(e) {
  const msg = String(e && e.message ? e.message : e);
  state.errors.push(msg);
  const el = $("error");
  el.textContent = msg;
  el.hidden = false;
}

async function load() {
  const found = await discover();
  state.source = found.source;
  state.loads++;
  hub = found.hub;
  $("source").textContent = found.source === "directory"
    ? `${found.things.length} device(s) from the Thing Description Directory (GET /things).`
    : `${found.things.length} device(s) from the servient's catalogue (no directory at /things).`;
  if (hub) {
    state.hub = hub.td.title;
    $("hub-name").textContent = hub.td.title;
    hubDevices = await readProperty(hub.td, "devices");
    health = await readProperty(hub.td, "health");
    healthAt = now();
  }
  const seen = new Set();
  for (const {td, url} of found.things) {
    seen.add(td.id);
    const key = hubKeyOf(td, hubDevices);
    const row = state.devices[td.id] || {lastAction: null, lastActionAt: null, rate: null};
    Object.assign(row, {id: td.id, key, title: td.title || td.id, family: td["tac:family"] || "", url,
      events: Object.keys(td.events || {})});
    state.devices[td.id] = row;
    if (!subs.has(td.id) && td.events && td.events.actionDetection) {
      subs.set(td.id, subscribeEvent(td, "actionDetection", (action) => {
        row.lastAction = action;
        row.lastActionAt = now();
        render();
      }, {prefer: "ws"}));
    }
  }
  for (const id of Object.keys(state.devices)) {
    if (!seen.has(id)) {
      delete state.devices[id];
      if (subs.has(id)) subs.get(id).close();
      subs.delete(id);
    }
  }
  render();
}

async function pollCounters() {
  if (!hub) return;
  try {
    const c = await readProperty(hub.td, "eventCounters");
    const t = now();
    if (lastCounters) {
      const dt = (t - lastCounters.t) / 1000;
      for (const row of Object.values(state.devices)) {
        const a = row.key && c.things[row.key], b = row.key && lastCounters.c.things[row.key];
        row.rate = a && b ? (events(a, row.events) - events(b, row.events)) / dt : null;
      }
    }
    lastCounters = {c, t};
    render();
  } catch (e) {
    state.errors.push(String(e));
  }
}

// events published so far (the counters also count property changes: leave those out)
function events(thing, names) {
  let n = 0;
  for (const name of names) n += (thing.byName || {})[name] || 0;
  return n;
}

function render() {
  if (renderQueued) return;
  renderQueued = true;
  requestAnimationFrame(() => {
    renderQueued = false;
    draw();
  });
}

function draw() {
  if (health) {
    state.hubState = health.state;
    setBadge($("hub-state"), health.state);
    $("hub-uptime").textContent = `up ${fmtDuration(health.uptimeSeconds + (now() - healthAt) / 1000)}`;
  }
  const body = document.querySelector("#fleet tbody");
  const rows = Object.values(state.devices).sort((a, b) => a.title.localeCompare(b.title));
  const t = now();
  body.replaceChildren(...rows.map((row) => {
    const h = (health && row.key && health.devices[row.key]) || null;
    row.health = h ? h.state : null;
    const tr = document.createElement("tr");
    tr.dataset.thing = row.id;
    tr.dataset.key = row.key || "";
    const link = `/twin/device.html?td=${encodeURIComponent(row.url)}`;
    tr.innerHTML = `
      <td><a href="${link}">${esc(row.title)}</a><div class="muted small">${esc(row.key || row.id)}</div></td>
      <td>${esc(row.family)}</td>
      <td><span class="badge"></span></td>
      <td class="num rate">${row.rate === null || row.rate === undefined ? "–" : row.rate.toFixed(1)}</td>
      <td class="action">${row.lastAction ? `<b>${esc(row.lastAction)}</b> <span class="muted small">${
        fmtAgo(t - row.lastActionAt)}</span>` : "–"}</td>`;
    setBadge(tr.querySelector(".badge"), row.health || "unknown", h && h.reason);
    tr.onclick = (e) => {
      if (e.target.tagName !== "A") location.href = link;
    };
    return tr;
  }));
}

function setBadge(el, value, title) {
  el.textContent = value;
  el.className = `badge state-${value}`;
  if (title) el.title = title;
}

const esc = (s) => String(s).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
const fmtAgo = (ms) => (ms < 1000 ? "just now" : ms < 60000 ? `${Math.round(ms / 1000)} s ago`
  : `${Math.round(ms / 60000)} min ago`);
function fmtDuration(s) {
  if (s === undefined) return "";
  if (s < 120) return `${Math.round(s)} s`;
  if (s < 7200) return `${Math.round(s / 60)} min`;
  return `${(s / 3600).toFixed(1)} h`;
}

function scheduleReload() {
  clearTimeout(reloadTimer);
  reloadTimer = setTimeout(() => load().catch(showError), 300);
}

async function main() {
  await load();
  if (hub) {
    observeProperty(hub.td, "health", (value) => {
      health = value;
      healthAt = now();
      render();
    });
  }
  if (state.source === "directory") {
    // W3C Discovery notifications: a Thing registered, updated or removed
    new SseStream(new URL("/events", location.href).href, ["thing_created", "thing_updated", "thing_deleted"],
      scheduleReload);
  } else {
    setInterval(scheduleReload, 5000);
  }
  await pollCounters();
  setInterval(pollCounters, 1000);
  setInterval(render, 1000); // keep "n s ago" current
  state.ready = true;
}

main().catch(showError);
