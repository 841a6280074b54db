// node-wot 0.9.2, the reference JavaScript WoT client, against a running hub.
//
// Usage: node nodewot.mjs <hub http url> [seconds to wait for notifications]
//
// Driven by tests/interop/test_nodewot.py. Every TD is fetched with
// WoT.requestThingDescription (node-wot's own TD schema check), then consumed;
// every notification's value() is read, which checks it against the
// affordance's data schema. The directory's write actions and the hub Thing's history actions
// are invoked too (what node-wot's codecs allow). Prints JSON lines on stdout:
//   {"ready": true}   once every subscription is open (the test then makes the
//                      hub do what guarantees one notification of each kind)
//   {"report": {...}} at the end: what each operation gave, errors as text.
// Exits 0 whatever the findings (the test asserts them); 1 only if the script itself broke.

import core from "@node-wot/core"; // CommonJS packages: named exports via the default one
import http from "@node-wot/binding-http";

const {Servient} = core;
const {HttpClientFactory} = http;

const base = process.argv[2].replace(/\/$/, "");
const waitS = Number(process.argv[3] || 10);

const say = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
const text = (e) => (e instanceof Error ? e.message : String(e)).slice(0, 500);

async function outcome(fn) {
  try {
    return {ok: true, value: await fn()};
  } catch (e) {
    return {ok: false, error: text(e)};
  }
}

async function getJSON(url) {
  const r = await fetch(url, {headers: {Accept: "application/json"}});
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return r.json();
}

const servient = new Servient();
servient.addClientFactory(new HttpClientFactory());
const WoT = await servient.start();

const report = {directory: {}, directoryWrites: {}, things: {}, hubActions: {}, history: {}, readOnlyWrite: {},
                unsubscribe: null, raw: {}};

// --- the directory: its own TD, then every TD it lists -------------------------------
const dirUrl = `${base}/.well-known/wot`;
report.directory.requestThingDescription = await outcome(async () => {
  const td = await WoT.requestThingDescription(dirUrl);
  return {title: td.title, context: td["@context"]};
});
report.directory.consume = await outcome(async () => {
  const td = await WoT.requestThingDescription(dirUrl);
  const dir = await WoT.consume(td);
  return Object.keys(dir.getThingDescription().properties || {});
});
report.directory.explore = await outcome(async () => {
  const process_ = await WoT.exploreDirectory(dirUrl);
  const ids = [];
  for await (const td of process_) ids.push(td.id);
  // exploreDirectory skips a TD failing node-wot's schema check and keeps only the last error
  return {ids, error: process_.error ? text(process_.error) : null};
});

// --- the directory's write actions, through its TD's forms (the hub runs open here) ---------
// node-wot checks each answer's Content-Type against the form's response.contentType (text/plain);
// it has no codec for application/merge-patch+json: an object is sent as "[object Object]"
const dirThing = await WoT.consume(await WoT.requestThingDescription(dirUrl));
const probe = {"@context": ["https://www.w3.org/2019/wot/td/v1", "https://www.w3.org/2022/wot/td/v1.1"],
               id: "urn:example:nodewot-probe", title: "node-wot probe",
               securityDefinitions: {nosec_sc: {scheme: "nosec"}}, security: ["nosec_sc"]};
const byId = {uriVariables: {id: probe.id}};
const writes = report.directoryWrites;
const retrieved = async () => (await (await dirThing.invokeAction("retrieveThing", undefined, byId)).value()).title;
writes.createThing = await outcome(async () => { await dirThing.invokeAction("createThing", probe, byId); });
writes.updateThing = await outcome(async () => {
  await dirThing.invokeAction("updateThing", {...probe, title: "updated"}, byId);
  return retrieved();
});
writes.partiallyUpdateThing = await outcome(
  () => dirThing.invokeAction("partiallyUpdateThing", {title: "x"}, byId).then(() => null));
writes.partiallyUpdateThingText = await outcome(async () => {
  await dirThing.invokeAction("partiallyUpdateThing", JSON.stringify({title: "patched"}), byId);
  return retrieved();
});
writes.deleteThing = await outcome(() => dirThing.invokeAction("deleteThing", undefined, byId).then(() => null));
writes.createAnonymousThing = await outcome(async () => {
  const {id: _, ...anonymous} = {...probe, title: "node-wot anonymous probe"};
  await dirThing.invokeAction("createAnonymousThing", anonymous);
  const found = await (await dirThing.invokeAction("searchJSONPath", undefined,
    {uriVariables: {query: "$[?(@.title=='node-wot anonymous probe')].id"}})).value();
  for (const id of found) await dirThing.invokeAction("deleteThing", undefined, {uriVariables: {id}});
  return found.length;
});

// --- the hub Thing's actions: replay first, so that its replay Thing is served too ----
const hubTD = await WoT.requestThingDescription(`${base}/wot/hub`);
const hub = await WoT.consume(hubTD);
const devices = await (await hub.readProperty("devices")).value();
const recorded = devices.find((d) => d.recorded && d.state === "ok");
report.hubActions.replay = await outcome(async () => {
  // the last 20 s at twice the speed: the tare the test made just before comes 10 s in
  const out = await hub.invokeAction("replay", {device: recorded.id, from: "-20s", speed: 2, loop: true});
  return out.value();
});

// history outputs are JSON Lines and MCAP: node-wot has no codec for either (value() refuses),
// the bytes are there (arrayBuffer())
for (const [name, input] of [["historyRecords", {device: recorded.id, from: "-5s", limit: 5}],
                             ["historyExport", {devices: [recorded.id], from: "-5s"}]]) {
  report.history[name] = {
    value: await outcome(async () => (await hub.invokeAction(name, input)).value()),
    bytes: await outcome(async () => {
      const raw = Buffer.from(await (await hub.invokeAction(name, input)).arrayBuffer()).toString("latin1");
      const first = raw.split("\n")[0];
      return {length: raw.length, magic: raw.slice(0, 8), firstLine: first.startsWith("{") ? JSON.parse(first) : null};
    }),
  };
}

// --- every Thing the hub serves (its catalogue) ---------------------------------------
const catalogue = await getJSON(`${base}/wot`);
const consumed = {};
for (const [id, path] of Object.entries(catalogue)) {
  const entry = (report.things[id] = {read: {}, events: {}, observe: {}});
  const url = new URL(path, base + "/").href;
  const td = await outcome(() => WoT.requestThingDescription(url));
  entry.requestThingDescription = td.ok ? {ok: true} : td;
  if (!td.ok) continue;
  const thing = await WoT.consume(td.value);
  consumed[id] = thing;
  entry.affordances = {properties: Object.keys(td.value.properties || {}).sort(),
                       events: Object.keys(td.value.events || {}).sort()};
  entry.readAllProperties = await outcome(async () => {
    const all = await thing.readAllProperties();
    const names = [];
    for (const [name, out] of all) {
      await out.value();
      names.push(name);
    }
    return names.sort();
  });
  await Promise.all(entry.affordances.properties.map(async (name) => {
    entry.read[name] = await outcome(async () => typeof (await (await thing.readProperty(name)).value()));
  }));
}

// --- raw images (issue 29): each camera device's rawImage through its image/png and image/jpeg forms
// (node-wot picks a form by index; its codec for images hands value() a string, the bytes are arrayBuffer())
for (const [id, thing] of Object.entries(consumed)) {
  const image = (thing.getThingDescription().properties || {}).rawImage;
  if (!image) continue;
  const entry = (report.raw[id] = {});
  for (const type of ["image/png", "image/jpeg"]) {
    const formIndex = image.forms.findIndex((f) => f.contentType === type);
    entry[type] = await outcome(async () => {
      const out = await thing.readProperty("rawImage", {formIndex});
      const bytes = Buffer.from(await out.arrayBuffer());
      const again = await (await thing.readProperty("rawImage", {formIndex})).value();
      return {formIndex, length: bytes.length, head: bytes.subarray(0, 4).toString("hex"), value: typeof again};
    });
  }
}

// --- subscriptions: every event of every Thing, contactInformation of every device ----
const counts = [];
function counter() {
  const c = {n: 0, bad: null};
  counts.push(c);
  const listener = async (out) => {
    try {
      await out.value(); // parsed and checked against the data schema
      c.n++;
    } catch (e) {
      c.bad = text(e);
    }
  };
  return {c, listener, error: (e) => (c.bad = text(e))};
}

const subscriptions = [];
const pending = [];
for (const [id, thing] of Object.entries(consumed)) {
  const td = thing.getThingDescription();
  const entry = report.things[id];
  for (const name of Object.keys(td.events || {})) {
    const {c, listener, error} = counter();
    entry.events[name] = c;
    pending.push(thing.subscribeEvent(name, listener, error).then(
      (s) => subscriptions.push(s), (e) => (c.bad = `subscribe: ${text(e)}`)));
  }
  if ((td.properties || {}).contactInformation) {
    const {c, listener, error} = counter();
    entry.observe.contactInformation = c;
    pending.push(thing.observeProperty("contactInformation", listener, error).then(
      (s) => subscriptions.push(s), (e) => (c.bad = `observe: ${text(e)}`)));
  }
}
await Promise.all(pending);
say({ready: true, subscriptions: subscriptions.length, things: Object.keys(consumed)});

const deadline = Date.now() + waitS * 1000;
while (Date.now() < deadline && counts.some((c) => c.n === 0 && c.bad === null)) {
  await new Promise((r) => setTimeout(r, 100));
}
// unsubscribing goes through the form declaring unsubscribeevent/unobserveproperty
report.unsubscribe = {stopped: 0, errors: []};
for (const s of subscriptions) {
  try {
    await s.stop();
    report.unsubscribe.stopped++;
  } catch (e) {
    report.unsubscribe.errors.push(text(e));
  }
}

// --- a write to a read-only property: refused, with a clear error ---------------------
const dev = Object.keys(consumed).find((id) => consumed[id].getThingDescription().properties?.skinShape);
report.readOnlyWrite.nodewot = await outcome(() => consumed[dev].writeProperty("skinShape", {shapeType: "barrel"}));
report.readOnlyWrite.http = await outcome(async () => {
  const href = consumed[dev].getThingDescription().properties.skinShape.forms[0].href;
  const r = await fetch(href, {method: "PUT", headers: {"Content-Type": "application/json"},
                               body: JSON.stringify({shapeType: "barrel"})});
  return {status: r.status, contentType: r.headers.get("content-type"), body: await r.text()};
});

// --- the last hub action: stop the replay started above -------------------------------
report.hubActions.stopReplay = await outcome(async () => {
  const out = await hub.invokeAction("stopReplay", {device: recorded.id});
  return out.value();
});

say({report});
await servient.shutdown();
// stdout to a pipe is asynchronous in Node: exit once everything written is out
process.stdout.write("", () => process.exit(0));
