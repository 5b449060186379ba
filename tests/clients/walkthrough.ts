// The README walkthrough through the TypeScript types generated from openapi/openapi.json by openapi-typescript
// (scripts/clients.sh generates them as kac.d.ts beside this file, type-checks it with `tsc --strict`, then runs
// it with node against a real server on loopback): every body below is typed by the document, and the type-level
// checks fail the compilation if a success body the walkthrough reads is `never` or `unknown`.
import type { components, paths } from "./kac";
import { readFileSync } from "node:fs";

type Schemas = components["schemas"];
type Json<R> = R extends { content: { "application/json": infer B } } ? B : never;
type Ok<Op, S extends number> = Op extends { responses: infer R } ? (S extends keyof R ? Json<R[S]> : never) : never;
type Typed<T> = [T] extends [never] ? "never" : unknown extends T ? "unknown" : "typed";

type Upload = Ok<paths["/v1/shapes"]["post"], 201>;
type Job = Ok<paths["/v1/jobs"]["post"], 202>;
type JobNow = Ok<paths["/v1/jobs/{id}"]["get"], 200>;
type Result = Ok<paths["/v1/results/{id}"]["get"], 200>;
type Found = Ok<paths["/v1/search"]["post"], 200>;
type Jobs = Ok<paths["/v1/jobs"]["get"], 200>;
type Shapes = Ok<paths["/v1/shapes"]["get"], 200>;
type Table = Ok<paths["/v1/analyses"]["get"], 200>;
type Compared = Ok<paths["/v1/compare"]["post"], 200>;
// Fails to compile when any of these bodies is untyped.
const typed: ["typed", "typed", "typed", "typed", "typed", "typed", "typed", "typed", "typed"] = [
  "typed" as Typed<Upload>, "typed" as Typed<Job>, "typed" as Typed<JobNow>, "typed" as Typed<Result>,
  "typed" as Typed<Found>, "typed" as Typed<Jobs>, "typed" as Typed<Shapes>, "typed" as Typed<Table>,
  "typed" as Typed<Compared>,
];

function check(condition: boolean, what: string): void {
  if (!condition) {
    console.error(`walkthrough.ts: ${what}`);
    process.exit(1);
  }
}

async function call<T>(base: string, method: string, path: string, body?: unknown, raw?: Buffer): Promise<T> {
  const r = await fetch(base + path, {
    method,
    headers: raw ? { "Content-Type": "application/octet-stream" } : body ? { "Content-Type": "application/json" } : {},
    body: raw ? new Uint8Array(raw).buffer : body ? JSON.stringify(body) : undefined,
  });
  check(r.ok, `${method} ${path}: ${r.status} ${await r.clone().text()}`);
  return (await r.json()) as T;
}

async function finished(base: string, job: Job): Promise<JobNow> {
  let now: JobNow = job;
  const deadline = Date.now() + 120_000;
  while (!["succeeded", "failed", "canceled"].includes(now.status)) {
    check(Date.now() < deadline, `job ${now.id} still ${now.status}`);
    await new Promise((r) => setTimeout(r, 200));
    now = await call<JobNow>(base, "GET", `/v1/jobs/${now.id}`);
  }
  check(now.status === "succeeded", `job ${now.id} ended ${now.status}`);
  return now;
}

async function main(base: string, sphere: string, torus: string): Promise<void> {
  check(typed.length === 9, "the type checks");
  const shape = await call<Upload>(base, "POST", "/v1/shapes?format=off", undefined, readFileSync(sphere));
  const table = await call<Table>(base, "GET", `/v1/analyses?shape_id=${shape.id}`);
  check(table.class === "triangle_mesh", `class ${table.class}`);
  const spectrum: Schemas["SpectrumJobRequest"] = { analysis: "spectrum", shape_id: shape.id, k: 10, eigenvectors: true };
  const job = await finished(base, await call<Job>(base, "POST", "/v1/jobs", spectrum));
  const result = await call<Result>(base, "GET", `/v1/results/${job.id}`);
  // The union of results narrows on `analysis`: past this line `result` is a SpectrumResult, every field typed.
  if (result.analysis !== "spectrum") throw new Error(`result ${result.analysis}`);
  check(result.shape_id === shape.id && result.completeness?.complete === true, "a complete spectrum");
  const exact = [0, 2, 2, 2, 6, 6, 6, 6, 6, 12];
  check(result.eigenvalues.every((v, i) => Math.abs(v - exact[i]) <= 0.03 * Math.max(exact[i], 1)), "eigenvalues");
  const eigenvectors = result.arrays?.["eigenvectors"];
  check(eigenvectors !== undefined && eigenvectors.rows === 642 && eigenvectors.cols === 10, "the eigenvectors' links");
  const npy = await fetch(base + eigenvectors!.npy);
  const bytes = new Uint8Array(await npy.arrayBuffer());
  check(bytes[0] === 0x93 && String.fromCharCode(...bytes.slice(1, 6)) === "NUMPY", "an .npy file");
  const other = await call<Upload>(base, "POST", "/v1/shapes?format=off", undefined, readFileSync(torus));
  for (const id of [shape.id, other.id]) {
    const fp: Schemas["FingerprintJobRequest"] = { analysis: "fingerprint", shape_id: id, options: { k: 20 } };
    await finished(base, await call<Job>(base, "POST", "/v1/jobs", fp));
  }
  const query: Schemas["SearchRequest"] = { shape_id: shape.id, k: 20, neighbours: 5 };
  const found = await call<Found>(base, "POST", "/v1/search", query);
  check(found.searched === 2 && found.neighbours.length === 1 && found.neighbours[0].shape_id === other.id, "search");
  const jobs = await call<Jobs>(base, "GET", "/v1/jobs");
  check(jobs.total === 3 && jobs.items.every((j) => j.status === "succeeded"), `jobs ${jobs.total}`);
  console.log("walkthrough.ts: ok");
}

main(process.argv[2], process.argv[3], process.argv[4]).catch((e) => {
  console.error(e);
  process.exit(1);
});
