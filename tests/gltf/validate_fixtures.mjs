// Runs the Khronos glTF validator (npm gltf-validator) over the well-formed fixtures the renderer's glTF tests
// write, and fails on any error. Usage: node validate_fixtures.mjs DIR NAME...
import { createRequire } from 'node:module';
import { readFileSync, existsSync } from 'node:fs';
import { join, dirname } from 'node:path';

const require = createRequire(join(process.cwd(), 'noop.js'));
const validator = require('gltf-validator');
const [dir, ...names] = process.argv.slice(2);
let failed = 0, checked = 0;
for (const name of names) {
  const file = join(dir, name);
  if (!existsSync(file)) {
    console.error(`missing fixture ${file}`);
    failed++;
    continue;
  }
  const bytes = new Uint8Array(readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: name,
    externalResourceFunction: (uri) => Promise.resolve(new Uint8Array(readFileSync(join(dirname(file), uri)))),
  });
  const errors = report.issues.numErrors;
  checked++;
  if (errors > 0) {
    failed++;
    console.error(`${name}: ${errors} error(s)`);
    for (const m of report.issues.messages.filter((m) => m.severity === 0)) console.error(`  ${m.code} ${m.pointer ?? ''}: ${m.message}`);
  } else {
    console.log(`${name}: valid (${report.issues.numWarnings} warnings, ${report.issues.numInfos} infos)`);
  }
}
console.log(`${checked - failed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
