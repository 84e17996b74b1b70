// Read an MCAP flight log with Foxglove's own reader (@mcap/core, which the Foxglove app opens files with) and check
// every message against Foxglove's published JSON schemas (@foxglove/schemas), then print one JSON summary.
//
//   node tools/mcap_js/read.mjs indexed LOG   # as the app opens a finished file: summary, chunk indexes, CRCs
//   node tools/mcap_js/read.mjs stream LOG    # as the app reads a file without a usable index: records in order
//
// Why: "logs open in Foxglove" was checked only with the Python mcap library that writes them. This reader is a
// different implementation of the format (TypeScript) and the one the app uses, so a fault of ours that our own
// library forgives shows here. tests/log/test_foxglove_reader.py compares its summary with the Python reader's.
//
// Summary: {mode, complete, error, profile, library, metadata, topics: {topic: {schema, schema_encoding,
// message_encoding, count, digest, json_errors, foxglove_schema, foxglove_errors, first_foxglove_error}}}.
// `digest`: sha256 of the sorted lines "log_time:publish_time:sequence:sha256(data)" of the topic's messages, the
// same rule as the test's Python side. `complete`: indexed, the summary was read; stream, the file's footer and
// closing magic were reached. `error`: what stopped the reader (null when nothing did).

import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import Ajv from "ajv";
import { createHash } from "node:crypto";
import { open, readFile } from "node:fs/promises";
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const published = require("@foxglove/schemas/jsonschema.js");

const OFFICIAL = new Map(
  Object.values(published)
    .filter((s) => typeof s?.title === "string" && s.title.startsWith("foxglove."))
    .map((s) => [s.title, s]),
);
const ajv = new Ajv({ strict: false, allErrors: false });
const validators = new Map();
const decoder = new TextDecoder("utf-8", { fatal: true });

function validatorFor(name) {
  if (!OFFICIAL.has(name)) return undefined;
  if (!validators.has(name)) validators.set(name, ajv.compile(OFFICIAL.get(name)));
  return validators.get(name);
}

const sha256 = (bytes) => createHash("sha256").update(bytes).digest("hex");

class Topics {
  constructor() {
    this.schemas = new Map(); // id -> {name, encoding, data}
    this.channels = new Map(); // id -> channel record
    this.byTopic = new Map(); // topic -> accumulator
  }

  schema(record) {
    this.schemas.set(record.id, record);
  }

  channel(record) {
    this.channels.set(record.id, record);
    this.topic(record);
  }

  topic(channel) {
    if (!this.byTopic.has(channel.topic)) {
      const schema = this.schemas.get(channel.schemaId);
      let schemaParses = null;
      if (schema && schema.encoding === "jsonschema") {
        try {
          JSON.parse(decoder.decode(schema.data));
          schemaParses = true;
        } catch {
          schemaParses = false;
        }
      }
      this.byTopic.set(channel.topic, {
        schema: schema ? schema.name : "",
        schema_encoding: schema ? schema.encoding : "",
        schema_parses: schemaParses,
        message_encoding: channel.messageEncoding,
        lines: [],
        json_errors: 0,
        foxglove_schema: schema ? OFFICIAL.has(schema.name) : false,
        foxglove_errors: 0,
        first_foxglove_error: null,
      });
    }
    return this.byTopic.get(channel.topic);
  }

  message(record) {
    const channel = this.channels.get(record.channelId);
    if (!channel) throw new Error(`message on unknown channel ${record.channelId}`);
    const acc = this.topic(channel);
    acc.lines.push(`${record.logTime}:${record.publishTime}:${record.sequence}:${sha256(record.data)}`);
    if (channel.messageEncoding !== "json") return;
    let value;
    try {
      value = JSON.parse(decoder.decode(record.data));
    } catch {
      acc.json_errors += 1;
      return;
    }
    const validate = validatorFor(acc.schema);
    if (validate && !validate(value)) {
      acc.foxglove_errors += 1;
      if (acc.first_foxglove_error === null) {
        acc.first_foxglove_error = `${acc.schema} at log time ${record.logTime}: ${ajv.errorsText(validate.errors)}`;
      }
    }
  }

  summary() {
    const topics = {};
    for (const [topic, acc] of [...this.byTopic].sort(([a], [b]) => (a < b ? -1 : a > b ? 1 : 0))) {
      const { lines, ...rest } = acc;
      lines.sort();
      topics[topic] = { ...rest, count: lines.length, digest: sha256(Buffer.from(lines.join("\n"))) };
    }
    return topics;
  }
}

async function readIndexed(path, decompressHandlers) {
  const handle = await open(path, "r");
  const size = BigInt((await handle.stat()).size);
  const readable = {
    size: async () => size,
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      const { bytesRead } = await handle.read(buffer, 0, buffer.length, Number(offset));
      if (bytesRead !== buffer.length) throw new Error(`short read at ${offset}: ${bytesRead} of ${length} bytes`);
      return buffer;
    },
  };
  const out = { mode: "indexed", complete: false, error: null, profile: null, library: null, metadata: [] };
  const topics = new Topics();
  try {
    const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
    out.complete = true;
    out.profile = reader.header.profile;
    out.library = reader.header.library;
    for (const schema of reader.schemasById.values()) topics.schema(schema);
    for (const channel of reader.channelsById.values()) topics.channel(channel);
    for await (const message of reader.readMessages({ validateCrcs: true })) topics.message(message);
    for await (const metadata of reader.readMetadata()) out.metadata.push(metadata.name);
    out.statistics_message_count = reader.statistics ? Number(reader.statistics.messageCount) : null;
  } catch (error) {
    out.error = String(error?.message ?? error);
  } finally {
    await handle.close();
  }
  return { ...out, topics: topics.summary() };
}

async function readStream(path, decompressHandlers) {
  const data = await readFile(path);
  const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  const out = { mode: "stream", complete: false, error: null, profile: null, library: null, metadata: [] };
  const topics = new Topics();
  try {
    reader.append(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
    for (let record; (record = reader.nextRecord()); ) {
      switch (record.type) {
        case "Header":
          out.profile = record.profile;
          out.library = record.library;
          break;
        case "Schema":
          topics.schema(record);
          break;
        case "Channel":
          topics.channel(record);
          break;
        case "Message":
          topics.message(record);
          break;
        case "Metadata":
          out.metadata.push(record.name);
          break;
        default:
          break;
      }
    }
    out.complete = reader.done();
    if (!out.complete) out.error = `the file ends inside a record (${reader.bytesRemaining()} bytes left unparsed)`;
  } catch (error) {
    out.error = String(error?.message ?? error);
  }
  return { ...out, topics: topics.summary() };
}

const [mode, path] = process.argv.slice(2);
if (!["indexed", "stream"].includes(mode) || !path) {
  process.stderr.write("usage: node read.mjs indexed|stream LOG\n");
  process.exit(2);
}
const decompressHandlers = await loadDecompressHandlers();
const summary = mode === "indexed" ? await readIndexed(path, decompressHandlers) : await readStream(path, decompressHandlers);
process.stdout.write(JSON.stringify(summary) + "\n");
