// The system test's Foxglove WebSocket client (tests/tests/bridge.rs): Foxglove's own
// `FoxgloveClient` from @foxglove/ws-protocol, not code of this project, over the `ws` package.
//
//   node bridge_client.js ws://127.0.0.1:PORT SECONDS [--watch] [--quick] [--offer A,B]
//
// --offer: the WebSocket subprotocol names to offer (default: foxglove.sdk.v1 and
// FoxgloveClient.SUPPORTED_SUBPROTOCOL, foxglove.websocket.v1). With foxglove.sdk.v1.1 the
// server advertises channels against a schema table; this script reads that table from the raw
// frames (this client package predates it) so the channels' schemas are checked the same way.
// --watch (the latency bench's topside): only subscribe to every channel and count messages
// for SECONDS (or until SIGTERM), then print the counts; no service calls.
// --quick: list channels and services, check their schemas, call `thrusterd/setpoint` with an
// out-of-range pitch (refused with the reason) and report once it is answered; no estimate.
//
// Every advertised schema (each channel's, each service's request and response) goes through
// Foxglove Studio's and Lichtblick's own JSON Schema parsers (foxglove_parser.js,
// lichtblick_parser.js); `schema_errors` lists what they refused, as the apps would show it.
//
// Otherwise lists the advertised channels and services, subscribes to every channel, counts
// and parses the messages, calls `thrusterd/estimate` once the daemon has published its status,
// calls `thrusterd/setpoint` with an out-of-range pitch (it must fail with the reason), keeps
// receiving for a while after the estimate and prints one JSON summary on stdout. It exits 0
// whenever it could report (the Rust test judges), 2 on a connection failure or timeout.
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const parsers = {
  foxglove: require("./foxglove_parser.js").parseJsonSchema,
  lichtblick: require("./lichtblick_parser.js").parseJsonSchema,
};

const url = process.argv[2];
const seconds = Number(process.argv[3] || "20");
const watchOnly = process.argv.includes("--watch");
const quick = process.argv.includes("--quick");
const offerAt = process.argv.indexOf("--offer");
// The Foxglove SDK's server negotiates "foxglove.sdk.v1" (the ws-protocol spec's current
// name); this client package predates the rename and speaks the same messages.
const offered =
  offerAt > 0
    ? process.argv[offerAt + 1].split(",")
    : ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL];
const ws = new WebSocket(url, offered);
// foxglove.sdk.v1.1's schema table (id -> {name, encoding, data}), read from the raw frames
// before the client handles them (listeners run in the order they were added).
const schemaTable = new Map();
ws.on("message", (data, isBinary) => {
  if (isBinary) return;
  try {
    const m = JSON.parse(String(data));
    if (m.op === "advertise" && Array.isArray(m.schemas)) {
      for (const s of m.schemas) schemaTable.set(s.id, s);
    }
  } catch (_) {}
});
const client = new FoxgloveClient({ ws });
const decoder = new TextDecoder();

const out = {
  offered,
  subprotocol: null,
  schemas_checked: 0,
  schema_errors: {},
  server_name: null,
  channels: {},
  services: {},
  counts: {},
  json_errors: 0,
  first: {},
  states_before_call: [],
  states_after_call: [],
  estimate: null,
  bad_setpoint: null,
  errors: [],
};
const byId = new Map();
const bySub = new Map();
const calls = new Map();
let nextCall = 1;
let estimateSent = false;
let estimateAnswered = null;

function finish(code) {
  process.stdout.write(JSON.stringify(out) + "\n");
  try {
    ws.close();
  } catch (_) {}
  setTimeout(() => process.exit(code), 50);
}

function call(name, request) {
  const svc = out.services[name];
  const callId = nextCall++;
  calls.set(callId, name);
  client.sendServiceCallRequest({
    serviceId: svc.id,
    callId,
    encoding: "json",
    data: new Uint8Array(Buffer.from(JSON.stringify(request))),
  });
  return callId;
}

function maybeCall() {
  if (watchOnly) return;
  if (estimateSent || !out.services["thrusterd/estimate"] || !out.services["thrusterd/setpoint"]) {
    return;
  }
  // The daemon answers only once it runs: wait for its first status on the live view.
  if (out.states_before_call.length === 0) {
    return;
  }
  estimateSent = true;
  call("thrusterd/setpoint", { pitch_deg: 100 });
  call("thrusterd/estimate", {});
}

client.on("open", () => {
  out.subprotocol = ws.protocol;
});
client.on("error", (e) => out.errors.push(String(e && e.message ? e.message : e)));
client.on("serverInfo", (info) => {
  out.server_name = info.name;
});
/// Runs both apps' parsers on one advertised schema; a refusal is kept under "PARSER what".
function checkSchema(what, name, encoding, text) {
  out.schemas_checked += 1;
  if (encoding !== "jsonschema") {
    out.schema_errors[what] = `schema encoding ${encoding}, not jsonschema`;
    return;
  }
  for (const [p, parse] of Object.entries(parsers)) {
    try {
      parse(JSON.parse(text), name);
    } catch (e) {
      out.schema_errors[`${p} ${what}`] = String(e && e.message ? e.message : e);
    }
  }
}

client.on("advertise", (channels) => {
  for (const c of channels) {
    // foxglove.sdk.v1.1: the schema by reference to the table.
    const t = c.schemaId != undefined ? schemaTable.get(c.schemaId) : undefined;
    const schemaName = t ? t.name : c.schemaName;
    const schemaEncoding = t ? t.encoding : c.schemaEncoding;
    const schema = t ? t.data : c.schema;
    byId.set(c.id, c);
    out.channels[c.topic] = {
      encoding: c.encoding,
      schemaName,
      schemaEncoding,
      schemaIsJson: (() => {
        try {
          return typeof JSON.parse(schema) === "object";
        } catch (_) {
          return false;
        }
      })(),
    };
    checkSchema(`channel ${c.topic}`, schemaName, schemaEncoding, schema);
    if (quick) continue;
    const sub = client.subscribe(c.id);
    bySub.set(sub, c);
  }
});
client.on("advertiseServices", (services) => {
  for (const s of services) {
    out.services[s.name] = { id: s.id, type: s.type };
    for (const part of ["request", "response"]) {
      const m = s[part];
      if (m) checkSchema(`service ${s.name} ${part}`, m.schemaName, m.schemaEncoding, m.schema);
    }
  }
  if (quick && !estimateSent && out.services["thrusterd/setpoint"]) {
    estimateSent = true;
    call("thrusterd/setpoint", { pitch_deg: 100 });
    return;
  }
  maybeCall();
});
client.on("message", ({ subscriptionId, data }) => {
  const c = bySub.get(subscriptionId);
  if (!c) return;
  out.counts[c.topic] = (out.counts[c.topic] || 0) + 1;
  let msg;
  try {
    msg = JSON.parse(decoder.decode(data));
  } catch (_) {
    out.json_errors += 1;
    return;
  }
  if (!(c.topic in out.first)) out.first[c.topic] = msg;
  if (c.topic === "status") {
    (estimateAnswered ? out.states_after_call : out.states_before_call).push(msg.state);
    maybeCall();
  }
});
client.on("serviceCallResponse", (r) => {
  const name = calls.get(r.callId);
  const text = decoder.decode(r.data);
  if (name === "thrusterd/estimate") {
    out.estimate = { ok: true, response: text };
    estimateAnswered = Date.now();
  } else if (name === "thrusterd/setpoint") {
    out.bad_setpoint = { ok: true, response: text };
  }
});
client.on("serviceCallFailure", (f) => {
  const name = calls.get(f.callId);
  if (name === "thrusterd/estimate") {
    out.estimate = { ok: false, message: f.message };
    estimateAnswered = Date.now();
  } else if (name === "thrusterd/setpoint") {
    out.bad_setpoint = { ok: false, message: f.message };
  }
});

// Done once the estimate was answered and 3 s of status followed, or at the deadline.
const started = Date.now();
process.on("SIGTERM", () => finish(0));
const timer = setInterval(() => {
  if (quick && out.bad_setpoint) {
    // A moment for late advertisements (channels appear with their first message).
    if (!out.quick_done) out.quick_done = Date.now();
    if (Date.now() - out.quick_done > 1000) {
      clearInterval(timer);
      finish(0);
    }
    return;
  }
  if (watchOnly) {
    if (Date.now() - started > seconds * 1000) {
      clearInterval(timer);
      finish(0);
    }
    return;
  }
  if (estimateAnswered && Date.now() - estimateAnswered > 3000 && out.bad_setpoint) {
    clearInterval(timer);
    finish(0);
  } else if (Date.now() - started > seconds * 1000) {
    clearInterval(timer);
    out.errors.push(`timeout after ${seconds} s`);
    finish(2);
  }
}, 50);
