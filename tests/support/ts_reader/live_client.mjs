// Watch a Foxglove live view with Foxglove's TypeScript client (@foxglove/ws-protocol over `ws`, subprotocol
// foxglove.sdk.v1): retry connecting until the server is up, subscribe to every channel advertised, decode
// each message (JSON, or Protobuf with the FileDescriptorSet advertised, as Foxglove does) and, when the server
// closes the connection (or after the time limit), print as one JSON line: every channel's schema and
// encodings, its message count, and each topic's first and last message.
// Usage: node live_client.mjs ws://127.0.0.1:PORT [SECONDS]
import wsProtocol from "@foxglove/ws-protocol"; // CommonJS: its exports come as the default
import { protobufFromBinaryDescriptor } from "@mcap/support";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const [url, seconds = "120"] = process.argv.slice(2);
const deadline = Date.now() + Number(seconds) * 1000;
const channels = {};
const byChannelId = new Map();
const bySubscription = new Map();
const first = {};
const last = {};
const text = new TextDecoder();
let subprotocol = null;
const statuses = []; // the server's status messages (a refused subscription, say)

function decoder(channel) {
  if (channel.encoding === "json") return (data) => JSON.parse(text.decode(data));
  const type = protobufFromBinaryDescriptor(Buffer.from(channel.schema, "base64")).lookupType(channel.schemaName);
  return (data) => type.toObject(type.decode(data), { defaults: true, longs: Number, enums: Number });
}

let reported = false;
function report() {
  if (reported) return;
  reported = true;
  // a pipe is written asynchronously: exit once the whole line is out
  process.stdout.write(JSON.stringify({ subprotocol, channels, first, last, statuses }) + "\n", () => process.exit(0));
}

function connect() {
  if (Date.now() > deadline) report();
  const ws = new WebSocket(url, ["foxglove.sdk.v1"]);
  let opened = false;
  ws.on("error", () => {
    if (!opened) setTimeout(connect, 20); // not up yet: try again
  });
  const client = new FoxgloveClient({ ws });
  client.on("open", () => {
    opened = true;
    subprotocol = ws.protocol;
  });
  client.on("advertise", (list) => {
    for (const channel of list) {
      channels[channel.topic] = {
        schemaName: channel.schemaName,
        encoding: channel.encoding,
        schemaEncoding: channel.schemaEncoding ?? null,
        messages: 0,
      };
      byChannelId.set(channel.id, { channel, decode: decoder(channel) });
      bySubscription.set(client.subscribe(channel.id), channel.id);
    }
  });
  client.on("status", (status) => statuses.push(status));
  client.on("message", ({ subscriptionId, data }) => {
    const entry = byChannelId.get(bySubscription.get(subscriptionId));
    if (!entry) return;
    const message = entry.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
    const topic = entry.channel.topic;
    channels[topic].messages += 1;
    if (!(topic in first)) first[topic] = message;
    last[topic] = message;
  });
  client.on("close", () => {
    if (opened) report();
  });
}

setTimeout(report, Math.max(0, deadline - Date.now())).unref();
connect();
