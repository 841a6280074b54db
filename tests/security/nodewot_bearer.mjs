// node-wot 0.9.2 against a hub whose TDs declare bearer security (tests/security/test_nodewot_bearer.py).
//
// Usage: node nodewot_bearer.mjs <TD url> <token> [seconds]
// Fetches the TD with the token (WoT.requestThingDescription sends no credentials: a
// client fetching a protected TD does it itself, like any other protected resource),
// gives node-wot the token for the Thing's id (servient.addCredentials), consumes the
// TD as it is served, reads a property and subscribes to events: over the long-poll forms a
// secured TD lists first, whose requests node-wot signs with the header (its SSE client sends
// no credential; docs/security.md). Prints one JSON line: {"security", "read", "events", "errors"}.

import core from "@node-wot/core";
import http from "@node-wot/binding-http";

const [url, token, seconds] = [process.argv[2], process.argv[3], Number(process.argv[4] || 8)];
const text = (e) => (e instanceof Error ? e.message : String(e)).slice(0, 300);
const out = {security: null, read: null, events: {}, errors: []};
let stopping = false;

const servient = new core.Servient();
servient.addClientFactory(new http.HttpClientFactory());
const WoT = await servient.start();

try {
  const r = await fetch(url, {headers: {Authorization: `Bearer ${token}`, Accept: "application/td+json"}});
  if (!r.ok) throw new Error(`TD: HTTP ${r.status}`);
  const td = await r.json();
  out.security = td.security;
  servient.addCredentials({[td.id]: {token}});
  const thing = await WoT.consume(td);
  try {
    out.read = await (await thing.readProperty("skinShape")).value();
  } catch (e) {
    out.errors.push(`read: ${text(e)}`);
  }
  const subs = [];
  for (const name of Object.keys(td.events || {})) {
    out.events[name] = 0;
    try {
      subs.push(await thing.subscribeEvent(name, async (d) => { await d.value(); out.events[name] += 1; },
                                           (e) => stopping || out.errors.push(`${name}: ${text(e)}`)));
    } catch (e) {
      out.errors.push(`subscribe ${name}: ${text(e)}`);
    }
  }
  await new Promise((res) => setTimeout(res, seconds * 1000));
  stopping = true; // stopping a long poll aborts its pending request, which node-wot reports as an error
  for (const s of subs) await s.stop().catch(() => {});
} catch (e) {
  out.errors.push(text(e));
}
process.stdout.write(JSON.stringify(out) + "\n");
await servient.shutdown().catch(() => {});
process.exit(0);
