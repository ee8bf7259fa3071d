// The live view's test client (tests/tests/view.rs): a viewer made of independent parts, the
// Foxglove WebSocket protocol's own client library (@foxglove/ws-protocol, over `ws`), protobufjs
// to decode the Foxglove schemas from the descriptors the server advertises, jpeg-js to decode the
// camera frames, ajv to check the JSON messages against the schemas advertised with them.
//
//   node client.js ws://127.0.0.1:PORT [--stall] [--count-only]
//
// It subscribes to every channel the server advertises and prints one JSON line when it has
// seen the channels (`{"ready": ...}`), then reads commands from stdin, one JSON object a line:
//   {"cmd": "call", "service": "/perturb/set", "request": {...}}  -> {"service", "reply"} or {"service", "error"}
//   {"cmd": "report"}  -> {"report": {topic: {count, schema, rate_hz, images, points, invalid, last}}}
//   {"cmd": "quit"}
// With --stall it stops reading the socket once subscribed (a viewer that hangs): the server's
// queue for it fills and must not hold anything else up. With --count-only it counts messages
// without decoding them (a viewer whose decoding runs elsewhere: benches/view/measure.py).
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");
const jpeg = require("jpeg-js");
const Ajv2020 = require("ajv/dist/2020").default;
const readline = require("readline");

const url = process.argv[2];
const stall = process.argv.includes("--stall");
const countOnly = process.argv.includes("--count-only");
const say = (o) => process.stdout.write(JSON.stringify(o) + "\n");

// The Rust SDK's server speaks the protocol under the name foxglove.sdk.v1 (the same messages
// as foxglove.websocket.v1); the client library leaves the name to the socket.
const ws = new WebSocket(url, ["foxglove.sdk.v1"]);
const client = new FoxgloveClient({ ws });
const ajv = new Ajv2020({ strict: false, allErrors: true });

const channels = new Map(); // channel id -> {topic, decode}
const bySubscription = new Map(); // subscription id -> channel id
const topics = new Map(); // topic -> tally
const services = new Map(); // name -> service
const calls = new Map(); // call id -> service name
let nextCall = 1;
let ready = false;
let hasServices = false;

function tally(topic) {
  if (!topics.has(topic)) {
    topics.set(topic, {
      count: 0, schema: null, first_ms: null, last_ms: null,
      images: {}, points: [], invalid: 0, errors: [], last: null,
    });
  }
  return topics.get(topic);
}

function decoderOf(ch) {
  if (ch.encoding === "protobuf") {
    const set = descriptor.FileDescriptorSet.decode(Buffer.from(ch.schema, "base64"));
    const type = protobuf.Root.fromDescriptor(set).lookupType(ch.schemaName);
    return (bytes) => type.toObject(type.decode(bytes), { longs: Number, bytes: Buffer });
  }
  if (ch.encoding === "json") {
    // Channels of one kind (every stream's stats) share a schema and its $id: compile it once.
    const schema = JSON.parse(ch.schema);
    const validate = (schema.$id && ajv.getSchema(schema.$id)) || ajv.compile(schema);
    return (bytes) => {
      const v = JSON.parse(Buffer.from(bytes).toString("utf8"));
      if (!validate(v)) {
        throw new Error(`${ch.topic}: not valid against ${ch.schemaName}: ${ajv.errorsText(validate.errors)}`);
      }
      return v;
    };
  }
  throw new Error(`${ch.topic}: unexpected encoding ${ch.encoding}`);
}

function take(topic, schemaName, bytes) {
  const t = tally(topic);
  const now = Date.now();
  t.count += 1;
  t.first_ms ??= now;
  t.last_ms = now;
  t.schema = schemaName;
  if (countOnly) return;
  const ch = [...channels.values()].find((c) => c.topic === topic);
  let msg;
  try {
    msg = ch.decode(bytes);
  } catch (e) {
    t.invalid += 1;
    if (t.errors.length < 3) t.errors.push(String(e.message || e));
    return;
  }
  if (schemaName === "foxglove.CompressedImage") {
    const img = jpeg.decode(msg.data, { useTArray: true, formatAsRGBA: false });
    const key = `${img.width}x${img.height}`;
    t.images[key] = (t.images[key] || 0) + 1;
    t.last = { format: msg.format, frame_id: msg.frameId, width: img.width, height: img.height };
  } else if (schemaName === "foxglove.PointCloud") {
    const n = msg.data.length / msg.pointStride;
    if (t.points.length < 50) t.points.push(n);
    t.last = { frame_id: msg.frameId, fields: msg.fields.map((f) => f.name), points: n };
  } else if (schemaName === "foxglove.CameraCalibration") {
    t.last = { width: msg.width, height: msg.height, k: msg.K || msg.k };
  } else {
    t.last = msg;
  }
}

function maybeReady() {
  if (ready || channels.size === 0 || (hasServices && services.size === 0)) return;
  ready = true;
  say({
    ready: true,
    channels: [...channels.values()].map((c) => ({ topic: c.topic, schema: c.schemaName, encoding: c.encoding })),
    services: [...services.keys()],
  });
  if (stall) {
    // Stop reading: the kernel's buffers fill, then the server's queue for this client.
    setTimeout(() => ws._socket.pause(), 200);
  }
}

client.on("serverInfo", (info) => {
  hasServices = info.capabilities.includes("services");
});
client.on("advertise", (list) => {
  for (const ch of list) {
    let decode;
    try {
      decode = decoderOf(ch);
    } catch (e) {
      say({ error: `cannot decode ${ch.topic}: ${e.message}` });
      continue;
    }
    channels.set(ch.id, { ...ch, decode });
    bySubscription.set(client.subscribe(ch.id), ch.id);
  }
  setTimeout(maybeReady, 300);
});
client.on("advertiseServices", (list) => {
  for (const s of list) services.set(s.name, s);
  setTimeout(maybeReady, 300);
});
client.on("message", ({ subscriptionId, data }) => {
  const ch = channels.get(bySubscription.get(subscriptionId));
  if (!ch) return;
  take(ch.topic, ch.schemaName, new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
});
client.on("serviceCallResponse", ({ callId, data }) => {
  const service = calls.get(callId);
  const text = Buffer.from(data.buffer, data.byteOffset, data.byteLength).toString("utf8");
  say({ service, reply: JSON.parse(text) });
});
client.on("serviceCallFailure", ({ callId, message }) => {
  say({ service: calls.get(callId), error: message });
});
client.on("error", (e) => say({ error: String(e && e.message ? e.message : e) }));
client.on("close", () => {
  say({ closed: true });
  process.exit(0);
});

readline.createInterface({ input: process.stdin }).on("line", (line) => {
  if (!line.trim()) return;
  const c = JSON.parse(line);
  if (c.cmd === "call") {
    const s = services.get(c.service);
    if (!s) return say({ service: c.service, error: "no such service" });
    const callId = nextCall++;
    calls.set(callId, c.service);
    client.sendServiceCallRequest({
      serviceId: s.id,
      callId,
      encoding: "json",
      data: new Uint8Array(Buffer.from(JSON.stringify(c.request))),
    });
  } else if (c.cmd === "report") {
    const report = {};
    for (const [topic, t] of topics) {
      const span = (t.last_ms - t.first_ms) / 1000;
      report[topic] = { ...t, rate_hz: span > 0 ? (t.count - 1) / span : 0 };
    }
    say({ report });
  } else if (c.cmd === "quit") {
    client.close();
    setTimeout(() => process.exit(0), 200);
  }
});
