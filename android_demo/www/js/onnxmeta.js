// The ONNX model's metadata_props, read from its bytes: onnxruntime-web's InferenceSession does
// not expose them (only input/output names and types), and the bundle check (bundle.js
// checkEmbedded) needs the copy of bundle.json the exporter stored there. A walk over the top
// level of the ModelProto's protobuf encoding: varints and length-delimited fields, every field
// but 14 skipped by its wire type (the graph, megabytes, in one step). Pure: Node and browser.

const METADATA_PROPS = 14; // ModelProto.metadata_props: repeated StringStringEntryProto {key = 1, value = 2}
const utf8 = new TextDecoder('utf-8', { fatal: true });

export class OnnxFormatError extends Error {
  constructor(message) {
    super(message);
    this.name = 'OnnxFormatError';
  }
}

/** [value, next position] of the varint at `pos` (values past 2^53 lose precision: only skipped). */
function varint(bytes, pos, end) {
  let value = 0;
  for (let i = 0; i < 10; i += 1) {
    if (pos >= end) throw new OnnxFormatError(`truncated varint at byte ${pos}`);
    const b = bytes[pos++];
    value += (b & 0x7f) * 2 ** (7 * i);
    if (b < 0x80) return [value, pos];
  }
  throw new OnnxFormatError(`varint longer than 10 bytes before byte ${pos}`);
}

/** The fields of the message in bytes[pos, end): {field, start, end} for length-delimited ones, {field} else. */
function* fields(bytes, pos, end) {
  while (pos < end) {
    const at = pos;
    const [key, next] = varint(bytes, pos, end);
    const field = Math.floor(key / 8);
    const wire = key % 8;
    if (field === 0) throw new OnnxFormatError(`field number 0 at byte ${at}`);
    pos = next;
    if (wire === 0) {
      pos = varint(bytes, pos, end)[1];
      yield { field };
    } else if (wire === 1 || wire === 5) {
      pos += wire === 1 ? 8 : 4;
      if (pos > end) throw new OnnxFormatError(`truncated fixed-size field ${field} at byte ${at}`);
      yield { field };
    } else if (wire === 2) {
      const [len, start] = varint(bytes, pos, end);
      if (len > end - start) throw new OnnxFormatError(`field ${field} at byte ${at} claims ${len} bytes, ${end - start} left`);
      pos = start + len;
      yield { field, start, end: pos };
    } else {
      throw new OnnxFormatError(`wire type ${wire} (field ${field}) at byte ${at}`);
    }
  }
}

function text(bytes, f, what) {
  if (f.start === undefined) throw new OnnxFormatError(`metadata_props ${what} is not a string`);
  try {
    return utf8.decode(bytes.subarray(f.start, f.end));
  } catch {
    throw new OnnxFormatError(`metadata_props ${what} is not UTF-8`);
  }
}

/**
 * metadata_props of the ONNX ModelProto in `bytes` (Uint8Array or ArrayBuffer) as a Map key ->
 * value (a repeated key: the last one, as onnxruntime). Throws OnnxFormatError on bytes that are
 * not a well-formed protobuf message.
 */
export function onnxMetadata(bytes) {
  const b = bytes instanceof Uint8Array ? bytes : new Uint8Array(bytes);
  const props = new Map();
  for (const f of fields(b, 0, b.length)) {
    if (f.field !== METADATA_PROPS) continue;
    if (f.start === undefined) throw new OnnxFormatError('metadata_props is not a message');
    let key = '';
    let value = '';
    for (const e of fields(b, f.start, f.end)) {
      if (e.field === 1) key = text(b, e, 'key');
      else if (e.field === 2) value = text(b, e, 'value');
    }
    props.set(key, value);
  }
  return props;
}
