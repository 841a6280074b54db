// node-wot 0.9.2 and credentials: what its HTTP clients send, and the hub's secured TDs as they are.
// Driven by tests/interop/test_nodewot_credentials.py.
//
// node nodewot_credentials.mjs matrix
//   Which security schemes node-wot applies, on which requests. A local recorder (127.0.0.1, free
//   port, no credential checked) serves one small TD per variant of securityDefinitions; for each,
//   a fresh ConsumedThing makes one first call: a property read, an SSE subscription or a long-poll
//   subscription (forms chosen by formIndex). The recorder notes each request's Authorization
//   header and access_token query parameter. Prints {"matrix": {variant: {client: {...}}}}.
//
// node nodewot_credentials.mjs hub <hub http url> <token> <device id> [seconds]
//   The secured hub's TDs, unedited: the TD fetched with the token in the header
//   (requestThingDescription sends none), servient.addCredentials({[td.id]: {token}}), consume; the
//   FIRST call on the Thing is a subscription (what used to leave node-wot without credentials),
//   then every event, contactInformation observed, every property read. Then the same with a
//   token the hub does not know. Prints {"hub": {...}, "refused": {...}}.
//
// Exits 0 whatever the findings (the test asserts them); 1 only if the script itself broke.

import http from "node:http";
import core from "@node-wot/core";
import httpBinding from "@node-wot/binding-http";

const TD_CONTEXT = ["https://www.w3.org/2019/wot/td/v1", "https://www.w3.org/2022/wot/td/v1.1"];
const text = (e) => (e instanceof Error ? e.message : String(e)).slice(0, 300);
const say = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function wot() {
  const servient = new core.Servient();
  servient.addClientFactory(new httpBinding.HttpClientFactory());
  return {servient, WoT: await servient.start()};
}

// --- matrix ------------------------------------------------------------------------------------

const BEARER_HEADER = {scheme: "bearer", in: "header", name: "Authorization", format: "opaque"};
const BEARER_QUERY = {scheme: "bearer", in: "query", name: "access_token", format: "opaque"};
const EITHER = {h: BEARER_HEADER, q: BEARER_QUERY, sc: {scheme: "combo", oneOf: ["h", "q"]}};
const TOKEN = "wott_00000000_measure";
const VARIANTS = {
  "bearer/header": {defs: {sc: BEARER_HEADER}, security: ["sc"], creds: {token: TOKEN}},
  "bearer/query": {defs: {sc: BEARER_QUERY}, security: ["sc"], creds: {token: TOKEN}},
  "apikey/header": {defs: {sc: {scheme: "apikey", in: "header", name: "Authorization"}}, security: ["sc"],
                    creds: {apiKey: TOKEN}},
  "apikey/query": {defs: {sc: {scheme: "apikey", in: "query", name: "access_token"}}, security: ["sc"],
                   creds: {apiKey: TOKEN}},
  "combo": {defs: EITHER, security: ["sc"], creds: {token: TOKEN}},
  // the Thing's security is the header; the stream form names a scheme of its own, as the hub's
  // SSE forms do (bearer_either_sc): the combo, or the header again
  "bearer/header, stream form combo": {defs: {...EITHER, b: BEARER_HEADER}, security: ["b"],
                                       creds: {token: TOKEN}, streamSecurity: ["sc"]},
  "bearer/header, stream form bearer/header": {defs: {b: BEARER_HEADER}, security: ["b"],
                                               creds: {token: TOKEN}, streamSecurity: ["b"]},
};
const CLIENTS = {
  read: {},
  sse: {subprotocol: "sse", "htv:methodName": "GET"},
  longpoll: {subprotocol: "longpoll"},
  "longpoll, htv:methodName GET": {subprotocol: "longpoll", "htv:methodName": "GET"},
};

async function matrix() {
  const seen = [];
  const server = http.createServer((req, res) => {
    const url = new URL(req.url, "http://x");
    seen.push({path: url.pathname, method: req.method, authorization: req.headers.authorization ?? null,
               access_token: url.searchParams.get("access_token")});
    if (req.headers.accept === "text/event-stream") {
      res.writeHead(200, {"Content-Type": "text/event-stream"});
      res.write('retry: 1000\n\nid: 1\ndata: "x"\n\n');
      return; // left open, as a stream is
    }
    res.writeHead(200, {"Content-Type": "application/json"});
    if (req.method === "HEAD") return res.end();
    setTimeout(() => res.end('"x"'), url.pathname.endsWith("/e") ? 50 : 0); // a long poll: soon
  });
  await new Promise((r) => server.listen(0, "127.0.0.1", r));
  const base = `http://127.0.0.1:${server.address().port}`;
  const out = {};
  let k = 0;
  for (const [variant, v] of Object.entries(VARIANTS)) {
    out[variant] = {};
    for (const [client, streamForm] of Object.entries(CLIENTS)) {
      const id = `urn:measure:${k}`;
      const path = `/${k++}`;
      const td = {
        "@context": TD_CONTEXT, id, title: "measure", securityDefinitions: v.defs, security: v.security,
        properties: {p: {type: "string", readOnly: true, forms: [
          {href: `${base}${path}/p`, op: ["readproperty"], "htv:methodName": "GET", contentType: "application/json"}]}},
        events: {e: {data: {type: "string"}, forms: [
          {href: `${base}${path}/e`, op: ["subscribeevent", "unsubscribeevent"], contentType: "application/json",
           ...streamForm, ...(v.streamSecurity ? {security: v.streamSecurity} : {})}]}},
      };
      const {servient, WoT} = await wot();
      servient.addCredentials({[id]: v.creds});
      const got = {first: null, thenRead: null};
      const thing = await WoT.consume(td);
      const step = async (fn) => {
        const before = seen.length;
        let error = null;
        try {
          await fn();
        } catch (e) {
          error = text(e);
        }
        await sleep(100);
        const requests = seen.slice(before).filter((r) => r.path.startsWith(path + "/")).map(
          ({method, authorization, access_token}) => ({method, authorization, access_token}));
        return {ok: error === null, error, requests};
      };
      const read = async () => { await (await thing.readProperty("p")).value(); };
      got.first = await step(client === "read" ? read : async () => {
        let n = 0;
        const sub = await thing.subscribeEvent("e", async (d) => { await d.value(); n++; }, () => {});
        for (let i = 0; i < 40 && n === 0; i++) await sleep(25);
        await sub.stop().catch(() => {});
        if (n === 0) throw new Error("no notification");
      });
      if (client !== "read") got.thenRead = await step(read);
      out[variant][client] = got;
      await servient.shutdown().catch(() => {});
    }
  }
  server.closeAllConnections?.();
  server.close();
  say({matrix: out});
}

// --- the secured hub ---------------------------------------------------------------------------

async function consumeHub(WoT, servient, url, token) {
  const r = await fetch(url, {headers: {Authorization: `Bearer ${token}`, Accept: "application/td+json"}});
  if (!r.ok) throw new Error(`TD: HTTP ${r.status}`);
  const td = await r.json();
  servient.addCredentials({[td.id]: {token}});
  return {td, thing: await WoT.consume(td)};
}

async function hub(base, token, device, seconds) {
  const url = `${base}/wot/${device}`;
  const report = {security: null, forms: {}, first: null, events: {}, observe: null, read: {}, errors: []};
  const {servient, WoT} = await wot();
  const subs = [];
  const counter = (name, into) => {
    into[name] = {n: 0, bad: null};
    return [async (d) => {
      try {
        await d.value(); // parsed and checked against the data schema
        into[name].n++;
      } catch (e) {
        into[name].bad = text(e);
      }
    }, (e) => (into[name].bad = text(e))];
  };
  try {
    const {td, thing} = await consumeHub(WoT, servient, url, token);
    report.security = td.security;
    for (const [name, ev] of Object.entries(td.events || {})) {
      report.forms[name] = ev.forms.map((f) => ({subprotocol: f.subprotocol ?? null, security: f.security ?? null,
                                                 scheme: new URL(f.href).protocol}));
    }
    const names = Object.keys(td.events || {});
    const [first, ...rest] = ["skinDeformedDetection", ...names.filter((n) => n !== "skinDeformedDetection")];
    report.first = first;
    subs.push(await thing.subscribeEvent(first, ...counter(first, report.events))); // the first call
    for (const name of rest) {
      try {
        subs.push(await thing.subscribeEvent(name, ...counter(name, report.events)));
      } catch (e) {
        report.events[name] = {n: 0, bad: `subscribe: ${text(e)}`};
      }
    }
    const observed = {};
    subs.push(await thing.observeProperty("contactInformation", ...counter("contactInformation", observed)));
    report.observe = observed.contactInformation;
    for (const name of Object.keys(td.properties || {})) {
      try {
        report.read[name] = typeof (await (await thing.readProperty(name)).value());
      } catch (e) {
        report.read[name] = `error: ${text(e)}`;
      }
    }
    const deadline = Date.now() + seconds * 1000;
    const waiting = () => [report.observe, report.events.skinDeformedDetection, report.events.actionDetection,
                           report.events.actionDetails]
      .some((c) => c.n === 0 && c.bad === null);
    while (Date.now() < deadline && waiting()) await sleep(100);
    // counted now: stopping a long poll aborts its pending request, which node-wot reports to the
    // error listener ("The user aborted a request.")
    report.events = structuredClone(report.events);
    report.observe = structuredClone(report.observe);
    for (const s of subs) await s.stop().catch((e) => report.errors.push(`stop: ${text(e)}`));
  } catch (e) {
    report.errors.push(text(e));
  }
  await servient.shutdown().catch(() => {});

  // a token the hub does not know: the TD is refused; given the TD, a subscription is refused too
  const refused = {td: null, subscribe: null};
  const bad = "wott_00000000_not-a-token";
  const other = await wot();
  try {
    await consumeHub(other.WoT, other.servient, url, bad);
    refused.td = "served";
  } catch (e) {
    refused.td = text(e);
  }
  try {
    const r = await fetch(url, {headers: {Authorization: `Bearer ${token}`}});
    const td = await r.json();
    other.servient.addCredentials({[td.id]: {token: bad}});
    const thing = await other.WoT.consume(td);
    const sub = await thing.subscribeEvent("skinDeformedDetection", () => {}, () => {});
    await sub.stop().catch(() => {});
    refused.subscribe = "subscribed";
  } catch (e) {
    refused.subscribe = text(e);
  }
  await other.servient.shutdown().catch(() => {});
  say({hub: report, refused});
}

const [mode, ...args] = process.argv.slice(2);
if (mode === "matrix") {
  await matrix();
} else if (mode === "hub") {
  await hub(args[0].replace(/\/$/, ""), args[1], args[2], Number(args[3] || 10));
} else {
  console.error("usage: nodewot_credentials.mjs matrix | hub <url> <token> <device> [seconds]");
  process.exit(1);
}
// stdout to a pipe is asynchronous in Node: exit once everything written is out
process.stdout.write("", () => process.exit(0));
