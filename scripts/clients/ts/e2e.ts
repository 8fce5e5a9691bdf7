// End to end through a TypeScript client generated from openapi.yaml (openapi-typescript types +
// openapi-fetch), used as an integrator would, without edits: submit a vectorize and a text job,
// follow each job's events (a full replay with ?from=0), read the job and download its SVG, PNG
// preview, PDF and first snapshot; the text job asks for 2 variations, and the second's SVG, PNG
// (at a chosen size) and PDF come through their own routes. `tsc` type-checks every call against the generated types first.
//
// Usage: node dist/e2e.js BASE_URL PNG_BASE64 — prints one line per job, exits 0 or throws.
import createClient from "openapi-fetch";
import { createParser, type EventSourceMessage } from "eventsource-parser";
import type { paths } from "./api.js";

declare const process: { argv: string[] };

const [base, png] = process.argv.slice(2);
const client = createClient<paths>({ baseUrl: base });

function check(ok: boolean, what: string): asserts ok {
  if (!ok) throw new Error(what);
}

async function submit(
  sent: Promise<{ data?: { id: string }; error?: unknown; response: Response }>,
): Promise<string> {
  const { data, error, response } = await sent;
  check(response.status === 202 && data !== undefined, `submit: ${response.status} ${JSON.stringify(error)}`);
  return data.id;
}

/** The event names of the job's stream, from a full replay to the terminal event. */
async function follow(id: string): Promise<string[]> {
  const { response } = await client.GET("/jobs/{id}/events", {
    params: { path: { id }, query: { from: 0 } },
    parseAs: "stream",
  });
  check(response.status === 200 && response.body !== null, `events: ${response.status}`);
  const names: string[] = [];
  let finished = false;
  const parser = createParser({
    onEvent(ev: EventSourceMessage) {
      JSON.parse(ev.data); // every event's data is one JSON object
      check(/^[0-9]+$/.test(ev.id ?? ""), `event without a resumable id: ${ev.id}`);
      names.push(ev.event ?? "message");
      if (["done", "failed", "cancelled"].includes(ev.event ?? "")) finished = true;
    },
  });
  const reader = response.body.getReader();
  const decoder = new TextDecoder();
  while (!finished) {
    const { value, done } = await reader.read();
    if (done) break;
    parser.feed(decoder.decode(value, { stream: true }));
  }
  await reader.cancel();
  return names;
}

async function bytes(promise: Promise<{ data?: ArrayBuffer; response: Response }>): Promise<Uint8Array> {
  const { data, response } = await promise;
  check(response.status === 200 && data !== undefined, `download: ${response.status}`);
  return new Uint8Array(data);
}

const text = (b: Uint8Array) => new TextDecoder().decode(b.slice(0, 4));

/** The longer side of a PNG, from its IHDR. */
function pngSide(png: Uint8Array): number {
  check(png[0] === 0x89 && text(png.slice(1)) === "PNG\r", "not a PNG");
  const v = new DataView(png.buffer, png.byteOffset, png.byteLength);
  return Math.max(v.getUint32(16), v.getUint32(20));
}

/** Variation 2 of a text job: its own SVG (not variation 1's), its PNG at 64 px, its PDF. */
async function variation(id: string): Promise<void> {
  const path = { params: { path: { id, i: 2 } }, parseAs: "arrayBuffer" } as const;
  const svg = await bytes(client.GET("/jobs/{id}/result/{i}.svg", path));
  const first = await bytes(client.GET("/jobs/{id}/result/{i}.svg", { params: { path: { id, i: 1 } }, parseAs: "arrayBuffer" }));
  check(text(svg) === "<svg" && new TextDecoder().decode(svg) !== new TextDecoder().decode(first), "variation 2 is not its own SVG");
  const png = await bytes(
    client.GET("/jobs/{id}/result/{i}.png", { params: { path: { id, i: 2 }, query: { size: 64 } }, parseAs: "arrayBuffer" }),
  );
  check(pngSide(png) === 64, `PNG side ${pngSide(png)}`);
  const pdf = await bytes(client.GET("/jobs/{id}/result/{i}.pdf", path));
  check(new TextDecoder().decode(pdf.slice(0, 5)) === "%PDF-", "not a PDF");
  console.log(`variation 2 of ${id}: svg ${svg.length} B, png ${png.length} B, pdf ${pdf.length} B`);
}

async function run(id: string): Promise<void> {
  const names = await follow(id);
  check(names[0] === "state" && names[names.length - 1] === "done", `events: ${names}`);
  check(names.includes("snapshot"), `no snapshot: ${names}`);
  const { data: job } = await client.GET("/jobs/{id}", { params: { path: { id } } });
  check(job?.status === "succeeded", `status: ${job?.status}`);
  const path = { params: { path: { id } }, parseAs: "arrayBuffer" } as const;
  const svg = await bytes(client.GET("/jobs/{id}/result.svg", path));
  const preview = await bytes(client.GET("/jobs/{id}/result.png", path));
  const pdf = await bytes(client.GET("/jobs/{id}/result.pdf", path));
  check(new TextDecoder().decode(pdf.slice(0, 5)) === "%PDF-", "not a PDF");
  const snap = await bytes(
    client.GET("/jobs/{id}/snapshots/{n}.svg", { params: { path: { id, n: 1 } }, parseAs: "arrayBuffer" }),
  );
  check(text(svg) === "<svg" && text(snap) === "<svg", "not an SVG");
  check(preview[0] === 0x89 && text(preview.slice(1)) === "PNG\r", "not a PNG");
  const big = await bytes(
    client.GET("/jobs/{id}/result.png", { params: { path: { id }, query: { size: 200 } }, parseAs: "arrayBuffer" }),
  );
  check(pngSide(big) === 200, `PNG side ${pngSide(big)}`);
  console.log(`${job.kind} ${id}: ${names.length} events, svg ${svg.length} B, png ${preview.length} B`);
}

const ids = [
  await submit(client.POST("/jobs", { body: { kind: "vectorize", image: png, paths: 4, steps: 6, seed: 7 } })),
  await submit(client.POST("/jobs", { body: { kind: "text", caption: "a red apple", paths: 4, steps: 6, seed: 9, variations: 2 } })),
];
for (const id of ids) await run(id);
await variation(ids[1]);
