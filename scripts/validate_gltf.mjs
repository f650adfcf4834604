// Validates .glb files with Khronos' glTF validator (npm `gltf-validator`); prints each file's
// error / warning / info / hint counts and every error and warning; exits 1 if any file has an
// error or a warning. The validator is loaded from the folder in GLTF_VALIDATOR_DIR (where
// `npm install gltf-validator` was run; see scripts/validate_gltf.sh), else from the usual
// module resolution.
//   node scripts/validate_gltf.mjs OUT/*.glb
import { createRequire } from "node:module";
import { readFileSync } from "node:fs";
import path from "node:path";

const base = process.env.GLTF_VALIDATOR_DIR ? path.resolve(process.env.GLTF_VALIDATOR_DIR) + "/" : import.meta.url;
const validator = createRequire(base)("gltf-validator");
const files = process.argv.slice(2);
if (files.length === 0) {
  console.error("usage: node scripts/validate_gltf.mjs FILE.glb...");
  process.exit(2);
}
let bad = 0;
for (const f of files) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(f)), { uri: path.basename(f), maxIssues: 0 });
  const i = report.issues;
  console.log(`${f}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints (validator ${report.validatorVersion})`);
  for (const m of i.messages) {
    if (m.severity <= 1) console.log(`  ${m.severity === 0 ? "error" : "warning"} ${m.code} at ${m.pointer ?? ""}: ${m.message}`);
  }
  if (i.numErrors > 0 || i.numWarnings > 0) bad += 1;
}
process.exit(bad > 0 ? 1 : 0);
