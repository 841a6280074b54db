// A small WoT consumer for the browser: the directory, TDs and the forms they declare.
//
// Nothing here knows the hub's URL layout: every request goes to a form's href
// (chosen by its op and protocol), except the two entry points of WoT
// Discovery, the directory's /things listing and /events notifications.

export class HttpError extends Error {
  constructor(status, message) {
    super(message);
    this.status = status;
  }
}

export const now = () => performance.timeOrigin + performance.now(); // ms since the epoch, sub-ms

// The hub's bearer token (docs/security.md), when it asks for one: given once in the URL
// fragment (#access_token=...), which never reaches the server or its logs, or typed when a
// request is refused; kept in sessionStorage (this tab only). Sent as the Authorization header
// on fetch; EventSource and WebSocket cannot set headers, so they carry ?access_token=.
const TOKEN_KEY = "wott-hub-token";
{
  const m = /(?:^#|&)access_token=([^&]+)/.exec(location.hash);
  if (m) {
    sessionStorage.setItem(TOKEN_KEY, decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname + location.search);
  }
}
export const token = () => sessionStorage.getItem(TOKEN_KEY);
export const authHeaders = (h = {}) => (token() ? {...h, Authorization: `Bearer ${token()}`} : h);
export function withToken(url) {
  const u = new URL(url, location.href);
  if (token()) u.searchParams.set("access_token", token());
  return u.href;
}
let asking = false;
function refused(r) {
  // 401: no token, or one revoked; ask once, then load the page again with it
  if (r.status !== 401 || asking) return;
  asking = true;
  const t = window.prompt("This hub needs an access token (wott-hub tokens create NAME --scope read):");
  if (t) {
    sessionStorage.setItem(TOKEN_KEY, t.trim());
    location.reload();
  }
}

export async function getJSON(url, accept = "application/json") {
  const r = await fetch(url, {headers: authHeaders({Accept: accept})});
  if (!r.ok) {
    refused(r);
    throw new HttpError(r.status, `${url}: ${r.status} ${await problem(r)}`);
  }
  return r.json();
}

async function problem(r) {
  try {
    const p = await r.json();
    return p.detail || p.title || "";
  } catch {
    return r.statusText;
  }
}

const opsOf = (f) => (Array.isArray(f.op) ? f.op : f.op ? [f.op] : []);
const isHttp = (href) => /^https?:|^\//.test(href) || !/^[a-z]+:/i.test(href);

export function href(td, form) {
  // drop URI template parts ({?offset,limit}); resolve against the TD's base
  return new URL(form.href.replace(/\{[^}]*\}/g, ""), td.base || location.href).href;
}

// The first form of ``affordance`` (or of the Thing) doing ``op``; ``kind``: "http", "sse" or "ws".
export function findForm(formsList, op, kind = "http") {
  for (const f of formsList || []) {
    if (!opsOf(f).includes(op)) continue;
    if (kind === "ws" && /^wss?:/.test(f.href)) return f;
    if (kind === "sse" && f.subprotocol === "sse" && isHttp(f.href)) return f;
    if (kind === "http" && isHttp(f.href) && !f.subprotocol) return f;
  }
  return null;
}

export async function readProperty(td, name) {
  const aff = (td.properties || {})[name];
  const f = aff && findForm(aff.forms, "readproperty", "http");
  if (!f) throw new Error(`${td.title}: no HTTP readproperty form for ${name}`);
  return getJSON(href(td, f));
}

export async function invokeAction(td, name, input) {
  const aff = (td.actions || {})[name];
  const f = aff && findForm(aff.forms, "invokeaction", "http");
  if (!f) throw new Error(`${td.title}: no HTTP invokeaction form for ${name}`);
  const r = await fetch(href(td, f), {
    method: f["htv:methodName"] || "POST",
    headers: authHeaders({"Content-Type": f.contentType || "application/json", Accept: "application/json"}),
    body: JSON.stringify(input),
  });
  if (!r.ok) throw new HttpError(r.status, `${name}: ${await problem(r)}`);
  return r.json();
}

// What both kinds of stream share: a state for the page to show, and reopening with
// exponential backoff (up to 5 s) after a drop, until closed.
class Reconnecting {
  constructor(onState, firstDelay) {
    this.onState = onState;
    this.state = "connecting";
    this.reconnects = 0;
    this.received = 0;
    this.firstDelay = this.backoff = firstDelay;
    this.closed = false;
  }

  _received() {
    this.received++;
    this.backoff = this.firstDelay;
  }

  _retry() {
    if (this.closed) return;
    this.reconnects++;
    this._set("reconnecting");
    setTimeout(() => this._open(), this.backoff);
    this.backoff = Math.min(this.backoff * 2, 5000);
  }

  _set(state) {
    this.state = state;
    if (this.onState) this.onState(state, this);
  }
}

// One Server-Sent Events stream that survives drops: on an error it reopens at
// once (then backing off up to 5 s) asking for what came after the last id it
// saw, so nothing is lost and nothing repeats. EventSource cannot set the
// Last-Event-ID header on a fresh connection, so the id goes in ``lastEventId=``,
// which the hub's SSE endpoints accept like the header.
//
// Framing (docs/hub.md): a stream of one affordance (one event, one observed
// property) carries unnamed messages, delivered as ``names[0]``; a stream of
// several (subscribeallevents, the directory's /events) names each message, and
// only the ``names`` listened to are delivered.
export class SseStream extends Reconnecting {
  constructor(url, names, onEvent, {after = null, onState = null} = {}) {
    super(onState, 100);
    this.url = url;
    this.names = names;
    this.onEvent = onEvent;
    this.lastEventId = after;
    this._open();
  }

  _open() {
    if (this.closed) return;
    const u = new URL(withToken(this.url));
    if (this.lastEventId !== null && this.lastEventId !== "") u.searchParams.set("lastEventId", this.lastEventId);
    const es = (this.es = new EventSource(u.href));
    es.onopen = () => this._set("open");
    const deliver = (name) => (e) => {
      if (e.lastEventId) this.lastEventId = e.lastEventId;
      this._received();
      let data;
      try {
        data = JSON.parse(e.data);
      } catch {
        return;
      }
      this.onEvent(name, data, e.lastEventId);
    };
    for (const name of this.names) es.addEventListener(name, deliver(name));
    if (this.names.length === 1) es.onmessage = deliver(this.names[0]); // one affordance: unnamed
    es.onerror = () => {
      es.close();
      this._retry();
    };
  }

  close() {
    this.closed = true;
    if (this.es) this.es.close();
    this._set("closed");
  }
}

// A subscription over the wotpy WebSocket binding (JSON-RPC: on_event / on_property_change).
// WebSockets do not count against the browser's six HTTP connections per host, which a
// fleet page with one SSE stream per device would exhaust.
export class WsSubscription extends Reconnecting {
  constructor(url, name, onData, {property = false, onState = null, onOpen = null} = {}) {
    super(onState, 200);
    this.url = url;
    this.onOpen = onOpen;
    this.name = name;
    this.onData = onData;
    this.property = property;
    this._open();
  }

  _open() {
    if (this.closed) return;
    const ws = (this.ws = new WebSocket(withToken(this.url)));
    ws.onopen = () => {
      const method = this.property ? "on_property_change" : "on_event";
      ws.send(JSON.stringify({jsonrpc: "2.0", method, params: {name: this.name}, id: 1}));
      this._set("open");
      if (this.onOpen) this.onOpen();
    };
    ws.onmessage = (m) => {
      const msg = JSON.parse(m.data);
      if (msg.error) {
        this._set("error: " + msg.error.message);
        return;
      }
      if (!msg.subscription) return;
      this._received();
      if (this.property && msg.name === "propertychange") this.onData(msg.data.value);
      else if (msg.name === this.name) this.onData(msg.data);
    };
    ws.onclose = () => this._retry();
  }

  close() {
    this.closed = true;
    if (this.ws) this.ws.close();
  }
}

// Subscribe to event ``name``: over SSE (resumable) or, with prefer "ws", the WebSocket form.
export function subscribeEvent(td, name, onData, {prefer = "sse", onState = null} = {}) {
  const aff = (td.events || {})[name];
  if (!aff) throw new Error(`${td.title}: no event ${name}`);
  const sse = findForm(aff.forms, "subscribeevent", "sse");
  const ws = findForm(aff.forms, "subscribeevent", "ws");
  if (ws && (prefer === "ws" || !sse)) return new WsSubscription(href(td, ws), name, onData, {onState});
  if (!sse) throw new Error(`${td.title}: no SSE or WebSocket form to subscribe to ${name}`);
  return new SseStream(href(td, sse), [name], (_n, data, id) => onData(data, id), {onState});
}

// Several events of one Thing on one SSE connection: the Thing's subscribeallevents form
// if it has one, else one stream per event. Returns the streams.
export function subscribeEvents(td, names, onEvent, {after = null, onState = null} = {}) {
  const all = findForm(td.forms, "subscribeallevents", "sse");
  if (all) return [new SseStream(href(td, all), names, onEvent, {after, onState})];
  return names.map((name) => {
    const f = findForm(((td.events || {})[name] || {}).forms, "subscribeevent", "sse");
    if (!f) throw new Error(`${td.title}: no SSE form to subscribe to ${name}`);
    return new SseStream(href(td, f), [name], onEvent, {after, onState});
  });
}

// Observe a property: over the WebSocket form when the TD has one (it holds none of the
// browser's six HTTP connections per host; see WsSubscription), else over SSE.
export function observeProperty(td, name, onValue, {prefer = "ws", onState = null} = {}) {
  const aff = (td.properties || {})[name];
  if (!aff) return null;
  const ws = findForm(aff.forms, "observeproperty", "ws");
  const sse = findForm(aff.forms, "observeproperty", "sse");
  if (ws && (prefer === "ws" || !sse)) {
    // no resume over wotpy's WebSocket: read the value again whenever the socket (re)opens
    const reread = () => readProperty(td, name).then(onValue, () => {});
    return new WsSubscription(href(td, ws), name, onValue, {property: true, onState, onOpen: reread});
  }
  if (!sse) return null;
  return new SseStream(href(td, sse), [name], (_n, value) => onValue(value), {onState});
}

// --- discovery ---------------------------------------------------------------------

export const isTactile = (td) => !!(td.properties && td.properties.skinNodes && td.properties.skinCells);
export const isHubThing = (td) => {
  const p = td.properties || {};
  return !!(p.devices && p.health && p.eventCounters);
};

function nextLink(header) {
  if (!header) return null;
  for (const part of header.split(/,(?=\s*<)/)) {
    const m = part.match(/<([^>]*)>\s*;(.*)/);
    if (m && /rel="?next"?/.test(m[2])) return new URL(m[1], location.href).href;
  }
  return null;
}

// Every TD of the directory at this origin (W3C WoT Discovery: GET /things, pages by Link
// rel=next), or null if there is no directory here.
export async function listDirectory() {
  let url = new URL("/things", location.href).href;
  const out = [];
  while (url) {
    const r = await fetch(url, {headers: authHeaders({Accept: "application/ld+json, application/json"})});
    if (r.status === 404 && out.length === 0) return null;
    refused(r);
    if (!r.ok) throw new HttpError(r.status, `${url}: ${r.status} ${await problem(r)}`);
    const page = await r.json();
    out.push(...(Array.isArray(page) ? page : page.members || []));
    url = nextLink(r.headers.get("Link"));
  }
  return out;
}

// The fleet: {source, things: [{td, url}], hub: {td, url}|null}. The directory when there is
// one; else the servient's catalogue (GET /wot), so the page still works on a hub without it.
export async function discover() {
  const dir = await listDirectory();
  let source, things;
  if (dir) {
    source = "directory";
    things = dir.map((td) => ({td, url: new URL(`/things/${encodeURIComponent(td.id)}`, location.href).href}));
  } else {
    source = "catalogue";
    const cat = await getJSON("/wot");
    things = await Promise.all(Object.values(cat).map(async (path) => {
      const url = new URL(path, location.href).href;
      return {td: await getJSON(url, "application/td+json"), url};
    }));
  }
  let hub = things.find((t) => isHubThing(t.td)) || null;
  if (!hub && source === "directory") {
    // the hub Thing is not in the directory: find it in the servient's catalogue (when the
    // list came from that catalogue, every TD in it was just read)
    try {
      const cat = await getJSON("/wot");
      const ids = Object.keys(cat).sort((a, b) => (b === "hub") - (a === "hub")); // the usual id first
      for (const path of ids.map((id) => cat[id])) {
        const url = new URL(path, location.href).href;
        const td = await getJSON(url, "application/td+json");
        if (isHubThing(td)) {
          hub = {td, url};
          break;
        }
      }
    } catch {
      hub = null;
    }
  }
  return {source, things: things.filter((t) => isTactile(t.td)), hub};
}

// The hub's id for a device TD: the entry of the hub Thing's ``devices`` property whose TD
// URL the device's forms live under (ids in the directory are URNs, the hub keys by path).
export function hubKeyOf(td, hubDevices) {
  const hrefs = [];
  for (const f of td.forms || []) hrefs.push(href(td, f));
  for (const kind of ["properties", "events", "actions"]) {
    for (const aff of Object.values(td[kind] || {})) for (const f of aff.forms || []) hrefs.push(href(td, f));
  }
  for (const d of hubDevices || []) {
    const base = d.td.replace(/\/$/, "") + "/";
    if (hrefs.some((h) => h.startsWith(base))) return d.id;
  }
  return null;
}
