// Eclipse Tahu's Sparkplug B payload codec (npm sparkplug-payload, pinned in
// package-lock.json) as a filter for tests/integration/test_sparkplug.py: it
// decodes what vmacd published and encodes commands, so vmacd's payloads are
// checked by the reference implementation and not only by the test's own
// reader. Installed by tests/npm_ci.sh (make test-integration).
//
// One JSON object per line on standard input, one answer per line out:
//   {"decode": BASE64}  -> {"ok": true, "payload": {timestamp, seq, metrics:
//                           [{name, type, value, timestamp, isNull}]}}
//   {"decode": BASE64, "births": {NAME: DATATYPE}}: a DDATA, whose metrics
//                           carry no datatype (the specification: the birth
//                           gave it), decoded as a host application does,
//                           with each metric's datatype from its device's
//                           DBIRTH (Tahu's decodePayload reads a value by it)
//   {"encode": PAYLOAD} -> {"ok": true, "b64": BASE64}; PAYLOAD as Tahu takes
//                           it ({timestamp, metrics: [{name, type, value}]})
//   anything that fails -> {"ok": false, "error": TEXT}
// 64-bit integers (Long) come out as decimal strings, bytes as base64.
import { createInterface } from "node:readline";
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const { decodePayload, encodePayload } = require("sparkplug-payload").get("spBv1.0");
const { Payload } = require("sparkplug-payload/lib/sparkplugPayloadProto").org.eclipse.tahu.protobuf;
const Long = require("long");

function plain(v) {
	if (v === null || v === undefined) return v ?? null;
	if (Long.isLong(v)) return v.toString();
	if (v instanceof Uint8Array) return { bytes: Buffer.from(v).toString("base64") };
	if (Array.isArray(v)) return v.map(plain);
	if (typeof v === "object") return Object.fromEntries(Object.entries(v).map(([k, x]) => [k, plain(x)]));
	return v;
}

function answer(line) {
	const req = JSON.parse(line);
	if ("decode" in req) {
		let bytes = Buffer.from(req.decode, "base64");
		if (req.births) {
			const raw = Payload.decode(bytes);
			for (const m of raw.metrics) {
				if (!m.datatype && m.name in req.births) m.datatype = req.births[m.name];
			}
			bytes = Payload.encode(raw).finish();
		}
		return { ok: true, payload: plain(decodePayload(bytes)) };
	}
	if ("encode" in req) {
		const p = req.encode;
		if (p.timestamp !== undefined) p.timestamp = Long.fromString(String(p.timestamp), true);
		for (const m of p.metrics ?? []) {
			if (/Int64$/.test(m.type) && typeof m.value === "string") m.value = Long.fromString(m.value, m.type === "UInt64");
		}
		return { ok: true, b64: Buffer.from(encodePayload(p)).toString("base64") };
	}
	throw new Error("neither decode nor encode");
}

for await (const line of createInterface({ input: process.stdin })) {
	if (!line.trim()) continue;
	let out;
	try {
		out = answer(line);
	} catch (e) {
		out = { ok: false, error: String(e && e.message ? e.message : e) };
	}
	process.stdout.write(JSON.stringify(out) + "\n");
}
