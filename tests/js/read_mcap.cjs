// Read a gnerun run log with the official TypeScript MCAP reader (@mcap/core) and validate every message
// against its channel's JSON Schema (ajv). A finished log is read through its index; a log without one (a
// killed run) is read as a stream, record by record, up to its last complete record.
// Usage: node read_mcap.cjs RUN.mcap; prints {"reader", "topics": {topic: messages}, "schemas", "invalid"}.
"use strict";
const fs = require("fs");
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const Ajv = require("ajv");
const fzstd = require("fzstd");

const decompressHandlers = { zstd: (data) => fzstd.decompress(data) };
const ajv = new Ajv({ strict: false, allErrors: true });
const decoder = new TextDecoder();
const out = { reader: "", topics: {}, schemas: {}, invalid: [] };
const validators = new Map();

function check(schema, channel, data) {
  out.schemas[channel.topic] = schema.name;
  if (!validators.has(schema.id)) {
    validators.set(schema.id, ajv.compile(JSON.parse(decoder.decode(schema.data))));
  }
  const validate = validators.get(schema.id);
  const message = JSON.parse(decoder.decode(data));
  out.topics[channel.topic] = (out.topics[channel.topic] || 0) + 1;
  if (!validate(message) && out.invalid.length < 20) {
    out.invalid.push({ topic: channel.topic, errors: ajv.errorsText(validate.errors) });
  }
}

async function indexed(bytes) {
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  for await (const message of reader.readMessages()) {
    const channel = reader.channelsById.get(message.channelId);
    check(reader.schemasById.get(channel.schemaId), channel, message.data);
  }
  out.reader = "McapIndexedReader";
}

function stream(bytes) {
  const reader = new McapStreamReader({ decompressHandlers });
  reader.append(bytes);
  const schemas = new Map();
  const channels = new Map();
  for (;;) {
    let record;
    try {
      record = reader.nextRecord();
    } catch (error) {
      break; // a truncated last record ends what can be read
    }
    if (record === undefined) break;
    if (record.type === "Schema") schemas.set(record.id, record);
    else if (record.type === "Channel") channels.set(record.id, record);
    else if (record.type === "Message") {
      const channel = channels.get(record.channelId);
      check(schemas.get(channel.schemaId), channel, record.data);
    }
  }
  out.reader = "McapStreamReader";
}

(async () => {
  const bytes = new Uint8Array(fs.readFileSync(process.argv[2]));
  try {
    await indexed(bytes);
  } catch (error) {
    out.topics = {};
    out.invalid = [];
    validators.clear();
    stream(bytes);
  }
  process.stdout.write(JSON.stringify(out) + "\n");
})();
