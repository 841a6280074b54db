// The Thingweb playground's own validators over TDs: @thing-description-playground/core
// (JSON, the TD JSON Schema, the full schema stating defaults, JSON-LD, its additional checks)
// and @thing-description-playground/assertions (the W3C TD assertions), as pinned by
// package-lock.json. Driven by tests/interop/test_td_validators.py.
//
// Usage: node validate_tds.mjs <input.json>
//   input: {"contexts": {"<context URL>": "<local file>"}, "tds": {"<name>": <TD>}}
// Prints one JSON line per TD:
//   {"name", "report": {json, schema, defaults, jsonld, additional}, "details": {...},
//    "log": [what the core logged], "assertions": {"counts": {pass: n, ...}, "fail": [{ID, Comment}]},
//    "defaults": {"all": [every error of the full schema], "besidesValueReadWriteOnly": [the same with
//    readOnly/writeOnly stated in the data schemas of values]}}
// then {"done": n}. Exits 0 whatever the findings (the test asserts them); 1 if the script broke.
//
// No network: JSON-LD contexts are served from the files given (the core's jsonld.toRDF uses
// jsonld's default document loader, replaced here on the very module instance the core
// requires); any other URL, and any HTTP(S) request at all, throws naming the URL.

import fs from "node:fs";
import http from "node:http";
import https from "node:https";
import {createRequire} from "node:module";
import path from "node:path";

const require = createRequire(import.meta.url);
const corePath = require.resolve("@thing-description-playground/core");
const fromCore = createRequire(corePath);
const jsonld = fromCore("jsonld"); // the instance the core's tdValidator calls
const core = require("@thing-description-playground/core");
// The assertions package checks a TD against each of its assertion schemas through util.validate,
// which builds a new Ajv and compiles the schema for every call: ~2 s of compiling per TD, the same
// for every TD. The package's index and assertionTests-td.js take util.validate from the one module
// instance when they load, so it is wrapped here first: the Ajv that util.validate builds for an
// assertion schema (its own options, formats and vocabulary) is kept by the schema's text and used
// again for the next TD. The verdicts are that Ajv's (validate, errors, errorsText), read before
// the next call as the package does; only the compiling is not repeated.
const assertionsDir = path.dirname(require.resolve("@thing-description-playground/assertions"));
const assertionsUtil = require(path.join(assertionsDir, "util.js"));
const buildAndValidate = assertionsUtil.validate;
const built = new Map(); // the assertion schema's JSON text -> the Ajv util.validate built for it
assertionsUtil.validate = (jsonData, schema, logFunc) => {
  const key = JSON.stringify(schema);
  const ajv = built.get(key);
  if (ajv === undefined) {
    const first = buildAndValidate(jsonData, schema, logFunc);
    built.set(key, first.ajvObject);
    return first;
  }
  return {valid: ajv.validate("assertion", jsonData), ajvObject: ajv};
};
const {tdAssertions} = require("@thing-description-playground/assertions");
const Ajv = fromCore("ajv");
const addFormats = fromCore("ajv-formats");
const addFormats2019 = fromCore("ajv-formats-draft2019");

const input = JSON.parse(fs.readFileSync(process.argv[2], "utf8"));
const contexts = {};
for (const [url, file] of Object.entries(input.contexts)) {
  contexts[url] = JSON.parse(fs.readFileSync(file, "utf8"));
}

const refuse = (what) => {
  throw new Error(`network access attempted (no network in these tests): ${what}`);
};
for (const mod of [http, https]) {
  mod.request = (u) => refuse(typeof u === "string" ? u : (u && (u.href || u.hostname)) || "?");
  mod.get = mod.request;
}
globalThis.fetch = async (u) => refuse(String(u));

jsonld.documentLoader = async (url) => {
  if (!(url in contexts)) refuse(`JSON-LD context ${url}`);
  return {contextUrl: null, documentUrl: url, document: contexts[url]};
};

// The assertions package reads its own files with our loader; it looks for the core's schema
// under its own node_modules, where npm does not put it (the core is hoisted).
const nestedCore = path.join(assertionsDir, "node_modules", "@thing-description-playground", "core");
const coreDir = path.dirname(corePath);
const fileLoader = (p) => fs.promises.readFile(p.startsWith(nestedCore) ? coreDir + p.slice(nestedCore.length) : p);

// The core's defaults check is its full schema (every default stated) and it reports its first
// error only; this compiles the same schema reporting every error, on the TD as served and on the
// TD with readOnly/writeOnly stated in the data schemas of values (see valueSchemas).
const ajv = addFormats2019(addFormats(new Ajv({strict: false, allErrors: true})));
const fullSchema = ajv.compile(JSON.parse(fs.readFileSync(path.join(coreDir, "td-schema-full.json"), "utf8")));
const fullErrors = (td) => (fullSchema(td) ? [] : fullSchema.errors.map(
  (e) => ({path: e.instancePath, keyword: e.keyword, message: e.message, params: e.params})));

// Every data schema describing a value, not an affordance: members and items of a property's
// value, action input/output, event data/subscription/dataResponse/cancellation, uriVariables and
// every schema below those.
function valueSchemas(td) {
  const out = [];
  const walk = (s) => {
    if (!s || typeof s !== "object" || Array.isArray(s)) return;
    out.push(s);
    below(s);
  };
  const below = (s) => {
    for (const m of Object.values(s.properties || {})) walk(m);
    for (const m of [].concat(s.items || [])) walk(m);
    for (const m of s.oneOf || []) walk(m);
    for (const m of Object.values(s.uriVariables || {})) walk(m);
  };
  for (const p of Object.values(td.properties || {})) below(p);
  for (const a of Object.values(td.actions || {})) {
    walk(a.input); walk(a.output);
    for (const m of Object.values(a.uriVariables || {})) walk(m);
  }
  for (const e of Object.values(td.events || {})) {
    for (const k of ["data", "subscription", "dataResponse", "cancellation"]) walk(e[k]);
    for (const m of Object.values(e.uriVariables || {})) walk(m);
  }
  for (const m of Object.values(td.uriVariables || {})) walk(m);
  for (const m of Object.values(td.schemaDefinitions || {})) walk(m);
  return out;
}

function withValueReadWriteOnly(td) {
  const copy = structuredClone(td);
  for (const s of valueSchemas(copy)) {
    if (!("readOnly" in s)) s.readOnly = false;
    if (!("writeOnly" in s)) s.writeOnly = false;
  }
  return copy;
}

let n = 0;
for (const [name, td] of Object.entries(input.tds)) {
  const text = JSON.stringify(td);
  const log = [];
  const logFunc = (m) => log.push(typeof m === "string" ? m : String(m));
  const out = {name, log};
  const {report, details} = await core.tdValidator(text, logFunc,
    {checkDefaults: true, checkJsonLd: true, checkTmConformance: true});
  out.report = report;
  out.details = details;
  out.defaults = {all: fullErrors(td), besidesValueReadWriteOnly: fullErrors(withValueReadWriteOnly(td))};
  try {
    const results = await tdAssertions([text], fileLoader, () => {});
    const counts = {};
    const fail = [];
    for (const r of results) {
      counts[r.Status] = (counts[r.Status] || 0) + 1;
      if (r.Status === "fail") fail.push({ID: r.ID, Comment: r.Comment || null});
    }
    out.assertions = {counts, fail};
  } catch (e) {
    out.assertions = {error: (e instanceof Error ? e.message : String(e)).slice(0, 1000)};
  }
  process.stdout.write(JSON.stringify(out) + "\n");
  n++;
}
process.stdout.write(JSON.stringify({done: n}) + "\n");
// stdout to a pipe is asynchronous in Node: exit once everything written is out
process.stdout.write("", () => process.exit(0));
