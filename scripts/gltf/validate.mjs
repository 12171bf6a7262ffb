// The Khronos glTF validator on one file: prints its report's counts and the first errors
// as one JSON line, and exits 0 (the caller reads the counts).
//
//   node scripts/gltf/validate.mjs FILE.glb|FILE.gltf
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';

const require = createRequire(process.env.GLTF_NODE_MODULES + '/');
const validator = require('gltf-validator');
const file = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
  maxIssues: 50,
  format: file.endsWith('.gltf') ? 'gltf' : 'glb',
});
const issues = report.issues;
console.log(JSON.stringify({
  errors: issues.numErrors,
  warnings: issues.numWarnings,
  infos: issues.numInfos,
  messages: issues.messages.filter((m) => m.severity <= 1).slice(0, 10)
    .map((m) => `${m.code} ${m.pointer ?? ''}: ${m.message}`),
  animations: report.info?.animationCount,
  nodes: report.info?.nodeCount,
}));
