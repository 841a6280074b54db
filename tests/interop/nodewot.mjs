// node-wot 0.9.2, the reference JavaScript WoT client, against a running hub.
//
// Usage: node nodewot.mjs <hub http url> [seconds to wait for notifications]
//
// Driven by tests/interop/test_nodewot.py. Every TD is fetched with
// WoT.requestThingDescription (node-wot's own TD schema check), then consumed;
// every notification's value() is read, which checks it against the
// affordance's data schema. Prints JSON lines on stdout:
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

const report = {directory: {}, things: {}, hubActions: {}, readOnlyWrite: {}, unsubscribe: null};

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

// --- the hub Thing's actions: replay first, so that its replay Thing is served too ----
const hubTD = await WoT.requestThingDescription(`${base}/wot/hub`);
const hub = await WoT.consume(hubTD);
const devices = await (await hub.readProperty("devices")).value();
const recorded = devices.find((d) => d.recorded && d.state === "ok");
report.hubActions.replay = await outcome(async () => {
  const out = await hub.invokeAction("replay", {device: recorded.id, from: "-60s", loop: true});
  return out.value();
});

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
process.exit(0);
