// The client of benches/foxglove_stream.sh: the reference Foxglove client (npm
// @foxglove/ws-protocol over `ws`) subscribes to every channel the server advertises and
// decodes every message with @foxglove/rosmsg2-serialization from the advertised schema, until
// the server closes the connection (the end of the run). Prints one JSON line: messages,
// payload bytes and decode failures per topic, and the `time` updates seen.
//
//   node foxglove_subscribe_all.js URL
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

const url = process.argv[2];
const perTopic = {};
const channels = new Map();
let times = 0;
let failures = 0;
let done = false;
function finish(why) {
  if (done) return;
  done = true;
  process.stdout.write(JSON.stringify({ end: why, times, failures, topics: perTopic }) + "\n", () => process.exit(0));
}
// Bounded: the bench's runs are well under this.
setTimeout(() => finish("timeout"), 600000);

const ws = new WebSocket(url, ["foxglove.websocket.v1"]);
const client = new FoxgloveClient({ ws });
client.on("error", () => {});
client.on("close", () => finish("closed"));
client.on("advertise", (list) => {
  for (const c of list) {
    if (c.encoding !== "cdr") continue;
    const reader = new MessageReader(parse(c.schema, { ros2: true }));
    perTopic[c.topic] = { messages: 0, bytes: 0 };
    channels.set(client.subscribe(c.id), { topic: c.topic, reader });
  }
});
client.on("time", () => times++);
client.on("message", (m) => {
  const c = channels.get(m.subscriptionId);
  if (!c) return;
  try {
    c.reader.readMessage(m.data);
  } catch (e) {
    failures++;
    return;
  }
  const t = perTopic[c.topic];
  t.messages++;
  t.bytes += m.data.byteLength;
});
