// Foxglove's own client library (@foxglove/ws-protocol, pinned by package-lock.json) against a real
// hub's Foxglove endpoint. Usage: node --experimental-websocket foxglove.mjs URL SECONDS
// Prints {"ready": [...topics subscribed]} once subscribed to every advertised channel, then, after
// SECONDS, {"report": ...}: per topic its channel (encoding, schema name and encoding, schema) and the
// messages received (count, log times, the first few payloads in base64). Half way it subscribes to a
// channel that does not exist and sends garbage: the server answers with statuses, this client goes on.
import wsProtocol from "@foxglove/ws-protocol"; // CommonJS: its default export

const { FoxgloveClient } = wsProtocol;

const [url, seconds] = [process.argv[2], Number(process.argv[3] ?? 5)];
// the SDK's server speaks the protocol under its current name; the library's own name offered too
const ws = new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // id -> channel
const subs = new Map(); // subscription id -> topic
const topics = {};
const statuses = [];
let serverInfo = null;
let afterGarbage = 0;
let garbageSent = false;

client.on("serverInfo", (info) => { serverInfo = info; });
client.on("status", (s) => statuses.push(s));
client.on("error", (e) => console.error("client error", e?.message ?? e));
client.on("advertise", (list) => {
  for (const ch of list) {
    channels.set(ch.id, ch);
    const sub = client.subscribe(ch.id);
    subs.set(sub, ch.topic);
    topics[ch.topic] = {
      encoding: ch.encoding, schemaName: ch.schemaName, schemaEncoding: ch.schemaEncoding,
      schema: ch.schema, count: 0, times: [], payloads: [],
    };
  }
  console.log(JSON.stringify({ ready: [...subs.values()].sort() }));
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = subs.get(subscriptionId);
  if (topic === undefined) return;
  const t = topics[topic];
  t.count += 1;
  if (t.times.length < 2000) t.times.push(timestamp.toString());
  if (t.payloads.length < 3) {
    t.payloads.push(Buffer.from(data.buffer, data.byteOffset, data.byteLength).toString("base64"));
  }
  if (garbageSent) afterGarbage += 1;
});

setTimeout(() => {
  client.subscribe(987654); // no such channel
  ws.send("this is not a protocol message");
  ws.send(new Uint8Array([0x7f, 1, 2, 3]));
  garbageSent = true;
}, (seconds * 1000) / 2);

setTimeout(() => {
  const report = JSON.stringify({ report: { serverInfo, topics, statuses, afterGarbage, protocol: ws.protocol } });
  client.close();
  // a pipe's writes are asynchronous in Node: exit once the whole line (~100 kB) is out, not before
  process.stdout.write(report + "\n", () => process.exit(0));
}, seconds * 1000);
