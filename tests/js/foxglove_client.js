// An independent Foxglove client for twin's tests: the reference client of the protocol
// (npm @foxglove/ws-protocol) over the `ws` package, decoding CDR with @foxglove/rosmsg2-serialization
// from the schema text the server advertises. Prints one JSON summary line on stdout.
//
// node foxglove_client.js URL SUBPROTOCOL MODE [MESH_URI] [COMMAND_TOPIC] [JOINT] [TARGET]
//   MODE "watch": subscribe to /joint_states and the IMU, decode a few messages, then exit.
//   MODE "full": also fetch MESH_URI, pause, step 50, publish a command moving JOINT to TARGET
//   (a Float64MultiArray holding the current positions with JOINT set), resume and watch it move.
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

const [url, subprotocol, mode, meshUri, commandTopic, joint, targetText] = process.argv.slice(2);
const target = Number(targetText);
const out = {
  subprotocol: null,
  serverInfo: null,
  channels: [],
  services: [],
  jointStates: 0,
  imu: 0,
  firstJointState: null,
  lastJointState: null,
  firstImu: null,
  times: [],
  asset: null,
  calls: {},
  timeWhilePaused: [],
  errors: [],
};
const deadline = setTimeout(() => finish("timeout"), 60000);
function finish(why) {
  clearTimeout(deadline);
  out.end = why;
  process.stdout.write(JSON.stringify(out) + "\n", () => process.exit(0));
}

const ws = new WebSocket(url, [subprotocol]);
ws.on("upgrade", (res) => {
  out.subprotocol = res.headers["sec-websocket-protocol"] || null;
});
const client = new FoxgloveClient({ ws });
const readers = new Map();
const subs = new Map();
const services = new Map();
let phase = "watch";
let lastTime = 0n;

client.on("error", (e) => out.errors.push(String(e)));
client.on("serverInfo", (info) => (out.serverInfo = info));
client.on("advertise", (channels) => {
  for (const c of channels) {
    out.channels.push({ id: c.id, topic: c.topic, schemaName: c.schemaName, encoding: c.encoding });
    if (c.encoding !== "cdr") continue;
    readers.set(c.id, new MessageReader(parse(c.schema, { ros2: true })));
    if (c.topic === "/joint_states" || c.schemaName === "sensor_msgs/msg/Imu") {
      subs.set(client.subscribe(c.id), c);
    }
  }
});
client.on("advertiseServices", (list) => {
  for (const s of list) {
    services.set(s.name, s.id);
    out.services.push(s.name);
  }
});
client.on("time", (t) => {
  lastTime = t.timestamp;
  if (out.times.length < 2000) out.times.push(Number(t.timestamp) * 1e-9);
  if (phase === "paused") out.timeWhilePaused.push(Number(t.timestamp) * 1e-9);
});
client.on("message", (m) => {
  const c = subs.get(m.subscriptionId);
  if (!c) return;
  const msg = readers.get(c.id).readMessage(m.data);
  if (c.topic === "/joint_states") {
    out.jointStates++;
    const stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9;
    const js = { stamp, receive: Number(m.timestamp) * 1e-9, name: msg.name, position: Array.from(msg.position) };
    if (!out.firstJointState) out.firstJointState = js;
    out.lastJointState = js;
  } else {
    out.imu++;
    if (!out.firstImu) out.firstImu = { orientation: msg.orientation, angular_velocity: msg.angular_velocity };
  }
  if (phase === "watch" && out.jointStates >= 20 && out.imu >= 5) {
    phase = "next";
    if (mode === "watch") finish("done");
    else fetch();
  }
  if (phase === "moving" && msg.name) {
    const i = msg.name.indexOf(joint);
    if (i >= 0 && Math.abs(msg.position[i] - target) < 0.05) {
      out.moved = { stamp: js_stamp(msg), position: msg.position[i] };
      finish("done");
    }
  }
});
function js_stamp(msg) {
  return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9;
}

function fetch() {
  client.on("fetchAssetResponse", (r) => {
    out.asset = { status: r.status, bytes: r.status === 0 ? r.data.byteLength : 0, error: r.error || null };
    call("/twin/pause", {}, (res) => {
      out.calls.pause = res;
      phase = "paused";
      setTimeout(() => {
        phase = "stepping";
        call("/twin/step", { steps: 50 }, (res2) => {
          out.calls.step = res2;
          command();
        });
      }, 400);
    });
  });
  client.fetchAsset(meshUri, 7);
}

const pending = new Map();
let nextCall = 1;
client.on("serviceCallResponse", (r) => {
  const done = pending.get(r.callId);
  pending.delete(r.callId);
  if (done) done(JSON.parse(new TextDecoder().decode(r.data)));
});
function call(name, request, done) {
  const id = nextCall++;
  pending.set(id, done);
  client.sendServiceCallRequest({
    serviceId: services.get(name),
    callId: id,
    encoding: "json",
    data: new TextEncoder().encode(JSON.stringify(request)),
  });
}

function command() {
  // The command: the current positions, in the server's command order (the joint states'
  // order), with JOINT moved to TARGET.
  const js = out.lastJointState;
  const data = js.position.slice();
  data[js.name.indexOf(joint)] = target;
  const chan = client.advertise({ topic: commandTopic, encoding: "json", schemaName: "std_msgs/msg/Float64MultiArray" });
  client.sendMessage(chan, new TextEncoder().encode(JSON.stringify({ data })));
  call("/twin/resume", {}, (res) => {
    out.calls.resume = res;
    phase = "moving";
  });
}
