// Lichtblick's JSON Schema parser (tests/node/lichtblick/parseJsonSchema.ts, its source file,
// unchanged; see tests/node/lichtblick/README.md), transpiled with the locked `typescript`
// package and evaluated here: the code Lichtblick runs, not a rule of ours.
//
//   const { parseJsonSchema, source } = require("./lichtblick_parser.js");
//   parseJsonSchema(JSON.parse(schemaText), schemaName)  // throws what the app shows
"use strict";

const fs = require("fs");
const path = require("path");
const ts = require("typescript");

function load() {
  const file = path.join(__dirname, "lichtblick", "parseJsonSchema.ts");
  const out = ts.transpileModule(fs.readFileSync(file, "utf8"), {
    compilerOptions: { module: ts.ModuleKind.CommonJS, target: ts.ScriptTarget.ES2020 },
    fileName: file,
  });
  const mod = { exports: {} };
  // Its imports: @protobufjs/base64 at run time; the others are types, which transpiling
  // removes (if one were left, it fails loudly here).
  const req = (name) => {
    if (name === "@protobufjs/base64") return require("@protobufjs/base64");
    throw new Error(`${file}: unexpected run-time import ${name}`);
  };
  // eslint-disable-next-line no-new-func
  new Function("require", "module", "exports", out.outputText)(req, mod, mod.exports);
  if (typeof mod.exports.parseJsonSchema !== "function") {
    throw new Error(`${file}: no parseJsonSchema after transpiling`);
  }
  return { parseJsonSchema: mod.exports.parseJsonSchema, source: file };
}

module.exports = load();
