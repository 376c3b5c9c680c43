// The contract, judged twice: every document of tests/contract/corpus/{valid,invalid} is validated by ajv (a real
// JSON Schema 2020-12 validator) against proto/schemas/job.schema.json, and submitted to a real tesserad. The corpus
// label, ajv's verdict and the daemon's verdict (202 accepted, 4xx refused) must all agree.
// Usage: node judge_corpus.mjs TESSERAD REPO_ROOT   (run from tests/js so that its node_modules resolve)
import { createRequire } from 'node:module';
import { spawn } from 'node:child_process';
import { readFileSync, readdirSync, mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const require = createRequire(join(process.cwd(), 'noop.js'));
const Ajv2020 = require('ajv/dist/2020').default;
const [tesserad, root] = process.argv.slice(2);

const ajv = new Ajv2020({ strict: false, allErrors: false });
const schemaDir = join(root, 'proto/schemas');
for (const f of readdirSync(schemaDir).filter((f) => f.endsWith('.schema.json')))
  ajv.addSchema(JSON.parse(readFileSync(join(schemaDir, f), 'utf8')));
const validateJob = ajv.getSchema('https://tessera.dev/schemas/job.schema.json');
if (!validateJob) throw new Error('job.schema.json has no $id https://tessera.dev/schemas/job.schema.json');

const dataDir = mkdtempSync(join(tmpdir(), 'tessera-contract-'));
const daemon = spawn(tesserad, ['--port', '0', '--data-dir', dataDir, '--threads', '1', '--max-jobs', '1',
                                '--log-level', 'warn'], { stdio: ['ignore', 'pipe', 'inherit'] });
const base = await new Promise((resolve, reject) => {
  let out = '';
  const timer = setTimeout(() => reject(new Error('tesserad did not start')), 20000);
  daemon.stdout.on('data', (chunk) => {
    out += chunk;
    const m = out.match(/listening on (http:\/\/\S+)/);
    if (m) { clearTimeout(timer); resolve(m[1]); }
  });
  daemon.on('exit', (code) => reject(new Error(`tesserad exited with ${code}`)));
});

let passed = 0, failed = 0;
for (const label of ['valid', 'invalid']) {
  const dir = join(root, 'tests/contract/corpus', label);
  for (const name of readdirSync(dir).filter((f) => f.endsWith('.json')).sort()) {
    const text = readFileSync(join(dir, name), 'utf8');
    const doc = JSON.parse(text);
    const byAjv = validateJob(doc);
    const res = await fetch(`${base}/v1/jobs`, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: text });
    const body = await res.text();
    const byDaemon = res.status === 202;
    const expected = label === 'valid';
    const ok = byAjv === expected && byDaemon === expected && (byDaemon || (res.status >= 400 && res.status < 500));
    if (ok) {
      passed++;
    } else {
      failed++;
      console.error(`${label}/${name}: corpus says ${expected ? 'valid' : 'invalid'}, ajv ${byAjv ? 'valid' : 'invalid'}` +
                    `${byAjv ? '' : ' (' + ajv.errorsText(validateJob.errors) + ')'}, daemon ${res.status} ${body.slice(0, 200)}`);
    }
  }
}
const live = await fetch(`${base}/livez`);
if (live.status !== 200) { console.error('the daemon stopped answering'); failed++; }
daemon.kill('SIGTERM');
await new Promise((r) => daemon.on('exit', r));
rmSync(dataDir, { recursive: true, force: true });
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
