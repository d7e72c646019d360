// Foxglove Studio's JSON Schema parser, `parseJsonSchema` of its `mcap-support` package: the
// function the app runs on every `jsonschema` channel (and Lichtblick, a fork of it, runs the
// same code) before it can show the channel. It is not published as a package of its own; the
// npm package @foxglove/studio-base (locked in package-lock.json) ships it inside its compiled
// bundle, as one concatenated module. This file takes that module's text from the installed
// package, unchanged, and evaluates it: the parser is Foxglove's code, not a rule of ours.
//
//   const { parseJsonSchema, source } = require("./foxglove_parser.js");
//   parseJsonSchema(JSON.parse(schemaText), schemaName)  // throws what the app shows
"use strict";

const fs = require("fs");
const path = require("path");

const START = ";// CONCATENATED MODULE: ../mcap-support/src/parseJsonSchema.ts";

function bundlePath() {
  const pkg = require.resolve("@foxglove/studio-base/package.json");
  return path.join(path.dirname(pkg), "assets", "index.js");
}

function load() {
  const file = bundlePath();
  const text = fs.readFileSync(file, "utf8");
  const start = text.indexOf(START);
  if (start < 0) {
    throw new Error(`${file}: no module ${START}`);
  }
  // The module ends where the bundle's next module (or external import) begins.
  const rest = text.slice(start + START.length);
  const ends = [rest.indexOf("\n// EXTERNAL MODULE:"), rest.indexOf("\n;// CONCATENATED MODULE:")]
    .filter((i) => i >= 0);
  if (ends.length === 0) {
    throw new Error(`${file}: the parser module does not end`);
  }
  const body = rest.slice(0, Math.min(...ends));
  if (!body.includes("function parseJsonSchema(")) {
    throw new Error(`${file}: the module holds no parseJsonSchema`);
  }
  // Its one import is @protobufjs/base64, used only for `contentEncoding: base64` strings,
  // which our schemas do not have: a stand-in that fails loudly if it is ever reached.
  const base64 = {
    length() {
      throw new Error("base64 string fields are not expected in thrusterd schemas");
    },
    decode() {
      throw new Error("base64 string fields are not expected in thrusterd schemas");
    },
  };
  // eslint-disable-next-line no-new-func
  const parse = new Function("base64", `${body}\nreturn parseJsonSchema;`)(base64);
  return { parseJsonSchema: parse, source: file };
}

module.exports = load();
