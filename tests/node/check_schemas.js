// Every schema thruster-bridge declares (`thruster-bridge --print-schemas` on stdin: each
// topic's channel, as in the recordings, and each service's request and response) through
// Foxglove Studio's own JSON Schema parser (foxglove_parser.js) and Lichtblick's
// (lichtblick_parser.js), including the channels a short system test never sees advertised
// (model, dynamics, input, config, ...).
//
//   thruster-bridge --print-schemas | node check_schemas.js
//
// Prints one JSON object: {"parsers": {"foxglove": FILE, "lichtblick": FILE}, "checked":
// ["PARSER what"], "errors": {"PARSER what": message}, "fields": {"PARSER what": number of
// fields the parser found at the top level}}. Exit 0 when it could report (the Rust test
// judges).
"use strict";

const parsers = {
  foxglove: require("./foxglove_parser.js"),
  lichtblick: require("./lichtblick_parser.js"),
};

let input = "";
process.stdin.on("data", (d) => (input += d));
process.stdin.on("end", () => {
  const all = JSON.parse(input);
  const out = { parsers: {}, checked: [], errors: {}, fields: {} };
  for (const [p, { source }] of Object.entries(parsers)) out.parsers[p] = source;
  const check = (what, name, text) => {
    for (const [p, { parseJsonSchema }] of Object.entries(parsers)) {
      const key = `${p} ${what}`;
      out.checked.push(key);
      try {
        const { datatypes } = parseJsonSchema(JSON.parse(text), name);
        out.fields[key] = datatypes.get(name).definitions.length;
      } catch (e) {
        out.errors[key] = String(e && e.message ? e.message : e);
      }
    }
  };
  for (const c of all.channels) check(`channel ${c.topic}`, c.schemaName, c.schema);
  for (const s of all.services) {
    check(`service ${s.name} request`, s.request.schemaName, s.request.schema);
    check(`service ${s.name} response`, s.response.schemaName, s.response.schema);
  }
  process.stdout.write(JSON.stringify(out) + "\n");
});
