// The Khronos glTF-Validator (npm `gltf-validator`, the reference validator engines' importers
// follow) on one GLB: prints its report's counts and first messages as JSON.
// Usage: node validate_glb.mjs FILE.glb   (GLTF_VALIDATOR_DIR: the package's folder)
import fs from 'node:fs';
import path from 'node:path';
import { pathToFileURL } from 'node:url';

const dir = process.env.GLTF_VALIDATOR_DIR;
const validator = (await import(pathToFileURL(path.join(dir, 'index.js')).href)).default;
const data = new Uint8Array(fs.readFileSync(process.argv[2]));
const report = await validator.validateBytes(data, { maxIssues: 200 });
const issues = report.issues;
console.log(JSON.stringify({
  validator: report.validatorVersion,
  errors: issues.numErrors,
  warnings: issues.numWarnings,
  infos: issues.numInfos,
  hints: issues.numHints,
  messages: issues.messages.slice(0, 20).map((m) => ({ severity: m.severity, code: m.code, message: m.message, pointer: m.pointer })),
  animations: report.info ? report.info.animationCount : null,
}));
