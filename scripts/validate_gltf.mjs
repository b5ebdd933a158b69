// Validates glTF 2.0 files (.glb or .gltf) with the Khronos glTF validator.
// Usage: node scripts/validate_gltf.mjs FILE... [--node-modules DIR] [--json]
// Exits 0 when no file has errors (warnings and infos are printed, not fatal), 1 when some
// file has errors, 2 on bad usage or when the validator module cannot be found. The module is
// looked up in DIR, $ARTEX_NODE_MODULES, then <repo>/build/node/node_modules
// (scripts/install_gltf_validator installs it there).
import { createRequire } from 'node:module';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const args = process.argv.slice(2);
const files = [];
let moduleDir = process.env.ARTEX_NODE_MODULES || '';
let printJson = false;
for (let i = 0; i < args.length; ++i) {
  if (args[i] === '--node-modules') moduleDir = args[++i] || '';
  else if (args[i] === '--json') printJson = true;
  else files.push(args[i]);
}
if (files.length === 0) {
  console.error('usage: node validate_gltf.mjs FILE... [--node-modules DIR] [--json]');
  process.exit(2);
}
const repo = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');
const candidates = [moduleDir, path.join(repo, 'build', 'node', 'node_modules')].filter(Boolean);
let validator = null;
for (const dir of candidates) {
  try {
    validator = createRequire(path.join(path.resolve(dir), 'index.js'))('gltf-validator');
    break;
  } catch (e) {
    // try the next location
  }
}
if (!validator) {
  console.error(`validate_gltf: module gltf-validator not found in ${candidates.join(', ')}` +
                ' (run scripts/install_gltf_validator)');
  process.exit(2);
}

let failed = false;
for (const file of files) {
  let bytes;
  try {
    bytes = new Uint8Array(fs.readFileSync(file));
  } catch (e) {
    console.error(`${file}: cannot read: ${e.message}`);
    failed = true;
    continue;
  }
  let report;
  try {
    report = await validator.validateBytes(bytes, {
      uri: file,
      maxIssues: 100,
      externalResourceFunction: (uri) =>
          Promise.reject(new Error(`external resource ${uri} not supported`)),
    });
  } catch (e) {
    console.log(`${file}: 1 errors (cannot validate: ${e && e.message ? e.message : e})`);
    failed = true;
    continue;
  }
  const issues = report.issues;
  if (printJson) console.log(JSON.stringify(report, null, 2));
  console.log(`${file}: ${issues.numErrors} errors, ${issues.numWarnings} warnings, ` +
              `${issues.numInfos} infos, ${issues.numHints} hints`);
  for (const m of issues.messages) {
    const severity = ['error', 'warning', 'info', 'hint'][m.severity] || String(m.severity);
    console.log(`  ${severity} ${m.code} ${m.pointer || ''}: ${m.message}`);
  }
  if (issues.numErrors > 0) failed = true;
}
process.exit(failed ? 1 : 0);
