#!/usr/bin/env python3
"""Cross-checks of the deployment files against each other and against the daemon.

Each file under deploy/ is parsed (YAML with PyYAML, the Dockerfile and the systemd unit line by line) and the
values that must agree are compared: the port, the probe paths (and that tesserad serves them), the data directory,
the uid, the image name and version, the stop grace, the names that tie the Kubernetes objects together, and that
every TESSERA_* variable they set and every key of their config files is one tesserad reads (server/config.cpp).
Given the built tesserad, it also has tesserad itself judge every config file and environment they set
(`tesserad --help` parses both first and exits 2 on a bad one).

    deploy_config_test.py REPO_ROOT [TESSERAD]
Prints one line per check; exits 1 when any check fails.
"""
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

import yaml

repo = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
tesserad = sys.argv[2] if len(sys.argv) > 2 else None
deploy = repo / "deploy"
failures = []
notes = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def load_all(path):
    return [d for d in yaml.safe_load_all(path.read_text()) if d is not None]


# --- the daemon's side -------------------------------------------------------------------------------------------
config_cpp = (repo / "server" / "config.cpp").read_text()
options = dict(re.findall(r'\{"--([a-z0-9-]+)",\s*"(TESSERA_[A-Z0-9_]+)"', config_cpp))
known_env = set(options.values())
check(len(known_env) >= 5, f"server/config.cpp names the flags and TESSERA_* variables ({len(known_env)} found)")
# Variables the deployment files may set for features tesserad does not have yet (none now).
pending_env = set()
m = re.search(r'"--grace-s".*?default (\d+)', config_cpp)
default_grace = int(m.group(1)) if m else 0
routes = "".join(p.read_text() for p in (repo / "server").rglob("*.cpp"))
for path in ("/livez", "/readyz"):
    check(f'"{path}"' in routes, f"tesserad serves {path}")
version = re.search(r"project\(tessera VERSION ([0-9.]+)", (repo / "CMakeLists.txt").read_text()).group(1)


def check_config_file(doc, where):
    """A config file: a JSON object whose keys are tesserad's flags without the dashes."""
    check(isinstance(doc, dict), f"{where} is a JSON object")
    unknown = [k for k in doc if k.replace("_", "-") not in options or k == "config"]
    check(not unknown, f"{where}: every key is a tesserad flag{(' (unknown: ' + ', '.join(unknown) + ')') if unknown else ''}")


def judge(where, config_text=None, env=None):
    """Lets the built tesserad parse a config file and an environment (--help returns after both are applied)."""
    if not tesserad:
        return
    with tempfile.TemporaryDirectory() as tmp:
        run_env = {k: v for k, v in os.environ.items() if not k.startswith("TESSERA_")}
        for k, v in (env or {}).items():
            if k in ("TESSERA_CONFIG", "TESSERA_TOKENS"):
                continue  # paths inside the deployment; the file itself is passed below
            run_env[k] = str(v)
        args = [tesserad]
        if config_text is not None:
            path = os.path.join(tmp, "tesserad.json")
            with open(path, "w") as f:
                f.write(config_text)
            args += ["--config", path]
        r = subprocess.run(args + ["--help"], env=run_env, capture_output=True, text=True, timeout=30)
        check(r.returncode == 0, f"tesserad accepts {where}" + (f": {r.stderr.strip().splitlines()[0]}" if r.returncode else ""))


def check_env(names, where):
    for name in sorted(names):
        if name in known_env:
            continue
        if name in pending_env:
            notes.append(f"{where} sets {name}, which this tesserad does not read yet")
            continue
        check(False, f"{where}: {name} is a variable tesserad reads")


# --- Dockerfile --------------------------------------------------------------------------------------------------
dockerfile = (deploy / "Dockerfile").read_text()
joined = re.sub(r"\\\n", " ", dockerfile)  # continuation lines joined
instr = [l.strip() for l in joined.splitlines() if l.strip() and not l.strip().startswith("#")]
froms = [l for l in instr if l.upper().startswith("FROM ")]
check(len(froms) >= 2 and any(" AS build" in f for f in froms) and any(" AS runtime" in f for f in froms),
      "Dockerfile is multi-stage (build and runtime)")
check(froms[-1].split()[-1] == "runtime", "Dockerfile: the last stage (the image) is runtime")
runtime = joined[joined.index("AS runtime"):]
for line in instr:
    if "apt-get install" in line:
        check("--no-install-recommends" in line, f"Dockerfile: apt-get install --no-install-recommends: {line[:60]}...")
check("cmake -S . -B build -G Ninja" in joined and "-DTESSERA_BUILD_TESTS=OFF" in joined and "Release" in joined,
      "Dockerfile builds with the project's CMake, Release, no tests")
df_env = dict(re.findall(r"(TESSERA_[A-Z_]+)=(\S+)", " ".join(l for l in instr if l.startswith("ENV"))))
df_user = re.search(r"^USER\s+(\d+)(?::(\d+))?", runtime, re.M)
check(df_user is not None and int(df_user.group(1)) != 0, "Dockerfile runs as a numeric non-root USER")
uid = int(df_user.group(1)) if df_user else -1
check(re.search(rf"TESSERA_UID={uid}\b", joined) is not None, f"Dockerfile: the tessera user's uid is the USER ({uid})")
df_volume = re.search(r"^VOLUME\s+(\S+)", runtime, re.M).group(1)
df_expose = int(re.search(r"^EXPOSE\s+(\d+)", runtime, re.M).group(1))
check(df_env.get("TESSERA_LISTEN") == "0.0.0.0", "Dockerfile: TESSERA_LISTEN=0.0.0.0")
check(df_env.get("TESSERA_DATA_DIR") == df_volume == "/var/lib/tessera", "Dockerfile: data dir = VOLUME /var/lib/tessera")
check(int(df_env.get("TESSERA_PORT", -1)) == df_expose == 8080, "Dockerfile: TESSERA_PORT = EXPOSE = 8080")
hc = re.search(r"^HEALTHCHECK .*CMD (.*)$", runtime, re.M)
check(hc is not None and "/readyz" in hc.group(1), "Dockerfile: HEALTHCHECK on /readyz")
check(re.search(r"^STOPSIGNAL\s+SIGTERM", runtime, re.M) is not None, "Dockerfile: STOPSIGNAL SIGTERM")
check(re.search(r"^ENTRYPOINT\s+\[\"/usr/bin/tesserad\"\]", runtime, re.M) is not None, "Dockerfile: ENTRYPOINT tesserad")
copy = re.search(r"^COPY --from=build (.*)$", runtime, re.M)
copied = copy.group(1).split() if copy else []
cli = {"/src/build/clients/cli/tessera", "/src/build/clients/cli/tessera-render"}
check(copied[-1:] == ["/usr/bin/"] and cli <= set(copied),
      "Dockerfile: the image has the tessera CLI and the tessera-render it runs, in /usr/bin")
check_env(df_env, "Dockerfile")
judge("the Dockerfile's environment", env=df_env)
df_version = re.search(r'org.opencontainers.image.version="([^"]+)"', dockerfile).group(1)
check(df_version == version, f"Dockerfile: image version label {df_version} = project version {version}")

ignore = [l.strip() for l in (repo / ".dockerignore").read_text().splitlines() if l.strip() and not l.startswith("#")]
for pattern in ("build*", "**/node_modules", ".git"):
    check(pattern in ignore, f".dockerignore leaves out {pattern}")

# --- compose.yaml ------------------------------------------------------------------------------------------------
compose = load_all(deploy / "compose.yaml")[0]
svc = compose["services"]["tesserad"]
image_name, image_tag = svc["image"].rsplit(":", 1)
check(image_name == "tessera" and image_tag == version, f"compose: image tessera:{version}")
check(svc["build"]["dockerfile"] == "deploy/Dockerfile" and svc["build"]["context"] == "..",
      "compose: builds deploy/Dockerfile from the repository root")
check(svc.get("restart") in ("always", "unless-stopped", "on-failure"), "compose: restart policy")
c_env = {k: str(v) for k, v in svc["environment"].items()}
check_env(c_env, "compose.yaml")
check(c_env.get("TESSERA_LISTEN") == "0.0.0.0", "compose: TESSERA_LISTEN=0.0.0.0")
port = int(c_env.get("TESSERA_PORT", df_env.get("TESSERA_PORT")))
check(any(str(p).endswith(f":{port}") for p in svc["ports"]), f"compose: publishes container port {port}")
data_dir = c_env.get("TESSERA_DATA_DIR", df_env.get("TESSERA_DATA_DIR"))
vol = [v for v in svc["volumes"] if v.split(":")[1] == data_dir]
check(len(vol) == 1 and vol[0].split(":")[0] in compose["volumes"], "compose: a named volume on the data dir")
test = " ".join(svc["healthcheck"]["test"])
check(f"127.0.0.1:{port}/readyz" in test, "compose: healthcheck on /readyz at the daemon's port")
compose_grace = svc.get("stop_grace_period")
judge("compose.yaml's environment", env=c_env)
c_daemon_grace = float(c_env.get("TESSERA_GRACE_S", default_grace))
check(compose_grace.endswith("s") and int(compose_grace[:-1]) >= c_daemon_grace + 5,
      f"compose: stop_grace_period {compose_grace} leaves the daemon's grace ({c_daemon_grace:g} s) a margin")

# --- Kubernetes --------------------------------------------------------------------------------------------------
k8s = {}
for f in sorted((deploy / "k8s").glob("*.yaml")):
    for d in load_all(f):
        k8s[d["kind"]] = d
for kind in ("Deployment", "Service", "PersistentVolumeClaim", "Secret", "ConfigMap", "Kustomization"):
    check(kind in k8s, f"k8s: a {kind}")
kust = k8s["Kustomization"]
listed = set(kust["resources"])
files = {f.name for f in (deploy / "k8s").glob("*.yaml")} - {"kustomization.yaml"}
check(listed == files, "k8s: kustomization.yaml lists every manifest")
dep = k8s["Deployment"]
spec = dep["spec"]
pod = spec["template"]["spec"]
check(spec["replicas"] == 1 and spec["strategy"]["type"] == "Recreate", "k8s: 1 replica, Recreate (one SQLite writer)")
check(spec["selector"]["matchLabels"].items() <= spec["template"]["metadata"]["labels"].items(),
      "k8s: the Deployment's selector matches its pods")
c = pod["containers"][0]
k_image, k_tag = c["image"].rsplit(":", 1)
check(k_image == image_name == "tessera", "k8s: image tessera, as compose and the image build")
check(any(i["name"] == k_image and i.get("newTag", k_tag) == version for i in kust.get("images", [])),
      "k8s: kustomization images: sets tessera's tag to the project version")
c_ports = {p["name"]: p["containerPort"] for p in c["ports"]}
k_env = {e["name"]: e.get("value") for e in c.get("env", [])}
check_env(k_env, "deployment.yaml")
check(k_env.get("TESSERA_LISTEN") == "0.0.0.0", "k8s: TESSERA_LISTEN=0.0.0.0")
check(c_ports.get("http") == int(k_env["TESSERA_PORT"]) == df_expose, "k8s: container port http = TESSERA_PORT = EXPOSE")
for probe, path in (("livenessProbe", "/livez"), ("readinessProbe", "/readyz")):
    g = c[probe]["httpGet"]
    check(g["path"] == path and g["port"] in ("http", c_ports["http"]), f"k8s: {probe} GET {path} on the http port")
check(c.get("startupProbe", {}).get("httpGet", {}).get("path") in (None, "/livez", "/readyz"), "k8s: startupProbe path")
for kind in ("requests", "limits"):
    check({"cpu", "memory"} <= set(c["resources"].get(kind, {})), f"k8s: resource {kind} for cpu and memory")
psc, csc = pod.get("securityContext", {}), c.get("securityContext", {})
check(psc.get("runAsNonRoot") is True and psc.get("runAsUser") == uid and psc.get("fsGroup") == uid,
      f"k8s: runAsNonRoot, runAsUser = fsGroup = the image's uid {uid}")
check(csc.get("readOnlyRootFilesystem") is True and csc.get("allowPrivilegeEscalation") is False
      and csc.get("capabilities", {}).get("drop") == ["ALL"], "k8s: read-only root, no privilege escalation, no caps")
vols = {v["name"]: v for v in pod["volumes"]}
mounts = {m["mountPath"]: m["name"] for m in c["volumeMounts"]}
data_vol = vols[mounts.get(k_env["TESSERA_DATA_DIR"], "")] if k_env["TESSERA_DATA_DIR"] in mounts else None
check(k_env["TESSERA_DATA_DIR"] == df_volume, "k8s: TESSERA_DATA_DIR is the image's data volume")
check(data_vol is not None and data_vol["persistentVolumeClaim"]["claimName"] == k8s["PersistentVolumeClaim"]["metadata"]["name"],
      "k8s: the data dir is mounted from the PersistentVolumeClaim")
check("ReadWriteOnce" in k8s["PersistentVolumeClaim"]["spec"]["accessModes"], "k8s: the PVC is ReadWriteOnce")
secret = k8s["Secret"]
secret_vols = [v for v in vols.values() if "secret" in v]
check(len(secret_vols) == 1 and secret_vols[0]["secret"]["secretName"] == secret["metadata"]["name"],
      "k8s: the tokens Secret is mounted as a volume")
sv = secret_vols[0] if secret_vols else {"name": "?", "secret": {}}
smount = next((p for p, n in mounts.items() if n == sv["name"]), None)
items = {i["key"]: i["path"] for i in sv["secret"].get("items", [])}
check(smount is not None and k_env.get("TESSERA_TOKENS") == f"{smount}/{items.get('tokens.json', 'tokens.json')}",
      "k8s: TESSERA_TOKENS names the mounted tokens file")
tokens = json.loads(secret["stringData"]["tokens.json"])
check(isinstance(tokens, list) and all({"token", "name", "role"} <= set(t) for t in tokens)
      and all("REPLACE" in t["token"] and len(t["token"]) < 16 for t in tokens),
      "k8s: the Secret holds a placeholder token too short for tesserad (it refuses to start with it)")
if tesserad:
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "tokens.json")
        with open(path, "w") as f:
            f.write(secret["stringData"]["tokens.json"])
        try:
            r = subprocess.run([tesserad, "--port", "0", "--data-dir", os.path.join(tmp, "data"), "--tokens", path],
                               capture_output=True, text=True, timeout=20)
            refused = r.returncode != 0 and "listening on" not in r.stdout
        except subprocess.TimeoutExpired:
            refused = False
        check(refused, "tesserad refuses to start with the placeholder Secret's tokens")
cm = k8s["ConfigMap"]
cm_vols = [v for v in vols.values() if v.get("configMap", {}).get("name") == cm["metadata"]["name"]]
cmount = next((p for p, n in mounts.items() if cm_vols and n == cm_vols[0]["name"]), None)
cm_items = {i["key"]: i["path"] for i in (cm_vols[0]["configMap"].get("items", []) if cm_vols else [])}
check(len(cm_vols) == 1 and cmount is not None, "k8s: the ConfigMap is mounted as a volume")
check(k_env.get("TESSERA_CONFIG") == f"{cmount}/{cm_items.get('tesserad.json', 'tesserad.json')}"
      and "tesserad.json" in cm["data"], "k8s: TESSERA_CONFIG names the ConfigMap's tesserad.json")
k_config = json.loads(cm["data"]["tesserad.json"])
check_config_file(k_config, "configmap.yaml tesserad.json")
judge("configmap.yaml's tesserad.json with the Deployment's environment", cm["data"]["tesserad.json"], k_env)
svc_k = k8s["Service"]
check(svc_k["spec"]["selector"].items() <= spec["template"]["metadata"]["labels"].items(),
      "k8s: the Service selects the Deployment's pods")
check(any(p["targetPort"] in ("http", c_ports["http"]) and p["port"] == c_ports["http"] for p in svc_k["spec"]["ports"]),
      "k8s: the Service's port targets the container's http port")
check(mounts.get("/tmp") is not None, "k8s: a writable /tmp beside the read-only root")
k_grace = pod.get("terminationGracePeriodSeconds")
k_daemon_grace = float(k_env.get("TESSERA_GRACE_S", k_config.get("grace-s", default_grace)))
check(k_grace >= k_daemon_grace + 5,
      f"k8s: terminationGracePeriodSeconds {k_grace} leaves the daemon's grace ({k_daemon_grace:g} s) a margin")

# --- systemd -----------------------------------------------------------------------------------------------------
unit = {}
for line in (deploy / "systemd" / "tesserad.service").read_text().splitlines():
    if "=" in line and not line.startswith("#"):
        k, v = line.split("=", 1)
        unit.setdefault(k.strip(), []).append(v.strip())
exec_start = unit["ExecStart"][0]
m = re.search(r"--data-dir\s+(\S+)", exec_start)
check(exec_start.startswith("/usr/bin/tesserad") and m and m.group(1) == "/var/lib/tessera",
      "systemd: ExecStart=/usr/bin/tesserad --data-dir /var/lib/tessera")
check(unit["ReadWritePaths"] == [m.group(1) if m else "?"] and unit["StateDirectory"] == ["tessera"],
      "systemd: the data dir is the only writable path, the StateDirectory")
check(unit["User"] == ["tessera"] and unit.get("DynamicUser") == ["no"], "systemd: User=tessera")
check(unit.get("Environment") == ["TESSERA_CONFIG=/etc/tessera/tesserad.json"],
      "systemd: TESSERA_CONFIG=/etc/tessera/tesserad.json (the packaged config file)")
check(unit.get("ExecReload") == ["/bin/kill -HUP $MAINPID"], "systemd: reload = SIGHUP (re-reads the tokens)")
for key, value in (("ProtectSystem", "strict"), ("NoNewPrivileges", "yes"), ("ProtectHome", "yes"),
                   ("PrivateTmp", "yes"), ("MemoryDenyWriteExecute", "yes"), ("CapabilityBoundingSet", ""),
                   ("Restart", "on-failure"), ("EnvironmentFile", "-/etc/tessera/tesserad.env")):
    check(unit.get(key) == [value], f"systemd: {key}={value}")
check(unit.get("RestrictAddressFamilies") == ["AF_INET AF_INET6 AF_UNIX"], "systemd: RestrictAddressFamilies")
check("@system-service" in unit.get("SystemCallFilter", []), "systemd: SystemCallFilter=@system-service")
s_grace = int(unit["TimeoutStopSec"][0])
deb_config_text = (deploy / "systemd" / "tesserad.json").read_text()
deb_config = json.loads(deb_config_text)
check_config_file(deb_config, "deploy/systemd/tesserad.json")
check("data-dir" not in deb_config and "data_dir" not in deb_config,
      "tesserad.json has no data-dir (the unit fixes it)")
check(deb_config.get("listen", "127.0.0.1") == "127.0.0.1", "tesserad.json listens on loopback by default")
s_daemon_grace = float(deb_config.get("grace-s", default_grace))
check(s_grace >= s_daemon_grace + 5,
      f"systemd: TimeoutStopSec={s_grace} leaves the daemon's grace ({s_daemon_grace:g} s) a margin")
env_file = (deploy / "systemd" / "tesserad.env").read_text()
env_names = set(re.findall(r"^#?(TESSERA_[A-Z0-9_]+)=", env_file, re.M))
check_env(env_names, "tesserad.env")
check("TESSERA_DATA_DIR" not in env_names, "tesserad.env does not offer TESSERA_DATA_DIR (the unit fixes it)")
env_set = dict(re.findall(r"^(TESSERA_[A-Z0-9_]+)=(.*)$", env_file, re.M))
judge("deploy/systemd/tesserad.json with tesserad.env", deb_config_text, env_set)
conffiles = (deploy / "debian" / "conffiles").read_text().split()
check(conffiles == ["/etc/tessera/tesserad.json", "/etc/tessera/tesserad.env"], "debian/conffiles: both settings files")

# --- kustomize, where a kubectl is installed ---------------------------------------------------------------------
kubectl = shutil.which("kubectl")
if kubectl:
    out = subprocess.run([kubectl, "kustomize", str(deploy / "k8s")], capture_output=True, text=True, timeout=60)
    built = [d for d in yaml.safe_load_all(out.stdout)] if out.returncode == 0 else []
    check(out.returncode == 0 and len(built) == len(files),
          f"kubectl kustomize deploy/k8s builds {len(files)} objects {out.stderr.strip()[:200]}")
else:
    notes.append("no kubectl here: `kubectl kustomize deploy/k8s` not run")

for n in notes:
    print(f"note {n}")
if failures:
    print(f"{len(failures)} deployment checks failed")
    sys.exit(1)
print("all deployment checks passed")
