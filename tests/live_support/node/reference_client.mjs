// The Foxglove WebSocket protocol's reference client (`FoxgloveClient` of @foxglove/ws-protocol,
// over the `ws` package) against a live view: connects with the protocol's published
// subprotocol, subscribes to every advertised channel, decodes every JSON payload, and writes
// what it saw as JSON when the server closes the connection.
// Usage: node reference_client.mjs URL OUT.json DEADLINE_S
import { writeFileSync } from "node:fs";
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
const [url, out, deadlineS] = process.argv.slice(2);
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const decoder = new TextDecoder();
const seen = {
  subprotocol: null,
  serverInfo: null,
  channels: {},
  messages: {},
  errors: [],
  closed: false,
};
const topicOf = new Map();

function finish(code) {
  writeFileSync(out, JSON.stringify(seen));
  process.exit(code);
}

client.on("open", () => {
  seen.subprotocol = ws.protocol;
});
client.on("serverInfo", (info) => {
  seen.serverInfo = info;
});
client.on("advertise", (channels) => {
  for (const c of channels) {
    seen.channels[c.topic] = {
      id: c.id,
      encoding: c.encoding,
      schemaName: c.schemaName,
      schemaEncoding: c.schemaEncoding ?? "",
      schema: c.schema,
    };
    topicOf.set(client.subscribe(c.id), c.topic);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = topicOf.get(subscriptionId);
  if (topic === undefined) {
    seen.errors.push(`data for unknown subscription ${subscriptionId}`);
    return;
  }
  let payload;
  try {
    payload = JSON.parse(decoder.decode(data));
  } catch (e) {
    seen.errors.push(`${topic}: payload is not JSON: ${e}`);
    return;
  }
  (seen.messages[topic] ??= []).push({ logTime: timestamp.toString(), payload });
});
client.on("error", (e) => {
  seen.errors.push(String(e?.message ?? e));
});
client.on("close", () => {
  seen.closed = true;
  finish(0);
});
setTimeout(() => {
  seen.errors.push(`the server did not close the connection within ${deadlineS} s`);
  finish(2);
}, Number(deadlineS) * 1000);
