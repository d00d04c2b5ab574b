// Read an MCAP log with Foxglove's TypeScript reader (@mcap/core, @mcap/nodejs, @mcap/support) and
// print, as one JSON line: every channel's topic, schema name and encodings, its message count as
// decoded here, and the first message of the channels named on the command line, decoded (JSON, or
// Protobuf with the FileDescriptorSet the log carries, as Foxglove's own reader does).
// Usage: node read_mcap.mjs LOG.mcap [TOPIC...]
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { loadDecompressHandlers, protobufFromBinaryDescriptor } from "@mcap/support";

const [path, ...decode] = process.argv.slice(2);
const handle = await open(path, "r");
try {
  const reader = await McapIndexedReader.Initialize({
    readable: new FileHandleReadable(handle),
    decompressHandlers: await loadDecompressHandlers(),
  });
  const channels = {};
  for (const [id, ch] of reader.channelsById) {
    const schema = reader.schemasById.get(ch.schemaId);
    channels[ch.topic] = {
      id,
      schema: schema?.name ?? null,
      schemaEncoding: schema?.encoding ?? null,
      messageEncoding: ch.messageEncoding,
      messages: 0,
    };
  }
  const byId = new Map(Object.values(channels).map((c) => [c.id, c]));
  const first = {};
  const text = new TextDecoder();
  const types = new Map();
  const decodeMessage = (ch, data) => {
    if (ch.messageEncoding !== "protobuf") return JSON.parse(text.decode(data));
    if (!types.has(ch.schemaId)) {
      const schema = reader.schemasById.get(ch.schemaId);
      types.set(ch.schemaId, protobufFromBinaryDescriptor(schema.data).lookupType(schema.name));
    }
    const type = types.get(ch.schemaId);
    return type.toObject(type.decode(data), { defaults: true, longs: Number, enums: Number });
  };
  for await (const msg of reader.readMessages()) {
    const ch = reader.channelsById.get(msg.channelId);
    byId.get(msg.channelId).messages += 1;
    if (decode.includes(ch.topic) && !(ch.topic in first)) {
      first[ch.topic] = decodeMessage(ch, msg.data);
    }
  }
  const statistics = reader.statistics ? Number(reader.statistics.messageCount) : null;
  console.log(JSON.stringify({ channels, first, statisticsMessageCount: statistics }));
} finally {
  await handle.close();
}
