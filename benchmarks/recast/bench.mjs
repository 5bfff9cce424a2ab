// Recast/Detour (the @recast-navigation WASM port) on one scene: build time and path queries.
// Reads one JSON object on stdin:
//   {positions: [x, y, z, ...] (Y up), indices: [...], cs, radius, repeats, queries: [[x0, z0, x1, z1], ...]}
// and prints {build_s: [...], polys, lengths: [...], query_ms: [...]} (lengths null where no path).
import { init, NavMeshQuery } from '@recast-navigation/core';
import { generateSoloNavMesh } from '@recast-navigation/generators';

const chunks = [];
for await (const chunk of process.stdin) chunks.push(chunk);
const job = JSON.parse(Buffer.concat(chunks).toString());
await init();

const positions = new Float32Array(job.positions);
const indices = new Uint32Array(job.indices);
const cs = job.cs;
const config = {
  cs,
  ch: 0.05,
  walkableRadius: Math.ceil(job.radius / cs),
  walkableHeight: Math.ceil(1.8 / 0.05),
  walkableClimb: 1,
  walkableSlopeAngle: 45,
  maxSimplificationError: cs,
  maxEdgeLen: 0,
  minRegionArea: 8,
  mergeRegionArea: 20,
  maxVertsPerPoly: 6,
  detailSampleDist: 6,
  detailSampleMaxError: 1,
  borderSize: 0,
};
const build_s = [];
let result;
for (let i = 0; i < job.repeats; i++) {
  if (result) result.navMesh.destroy();
  const t0 = process.hrtime.bigint();
  result = generateSoloNavMesh(positions, indices, config);
  build_s.push(Number(process.hrtime.bigint() - t0) / 1e9);
  if (!result.success) {
    console.log(JSON.stringify({ error: result.error }));
    process.exit(1);
  }
}
const query = new NavMeshQuery(result.navMesh);
const lengths = [];
const query_ms = [];
const half = { x: 0.5, y: 1.0, z: 0.5 };
for (const [x0, z0, x1, z1] of job.queries) {
  const t0 = process.hrtime.bigint();
  const out = query.computePath({ x: x0, y: 0, z: z0 }, { x: x1, y: 0, z: z1 }, { halfExtents: half, maxPathPolys: 4096, maxStraightPathPoints: 1024 });
  query_ms.push(Number(process.hrtime.bigint() - t0) / 1e6);
  const p = out.path;
  if (!out.success || p.length < 2) {
    lengths.push(null);
    continue;
  }
  const end = p[p.length - 1];
  if (Math.hypot(end.x - x1, end.z - z1) > 0.05) {
    lengths.push(null); // Detour returned a partial path
    continue;
  }
  let len = 0;
  for (let k = 1; k < p.length; k++) len += Math.hypot(p[k].x - p[k - 1].x, p[k].z - p[k - 1].z);
  lengths.push(len);
}
let polys = 0;
const tile = result.navMesh.getTile(0);
if (tile) polys = tile.header().polyCount();
console.log(JSON.stringify({ build_s, polys, lengths, query_ms }));
