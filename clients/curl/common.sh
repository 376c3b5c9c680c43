# Shared by the tessera curl scripts (sourced, not run). Needs curl and python3.
TESSERA_URL=${TESSERA_URL:-http://127.0.0.1:8080}
TESSERA_URL=${TESSERA_URL%/}
# TESSERA_TOKEN, when set, goes along as "Authorization: Bearer" (daemons started with --tokens need it).
TESSERA_AUTH=()
if [[ -n ${TESSERA_TOKEN:-} ]]; then TESSERA_AUTH=(-H "Authorization: Bearer $TESSERA_TOKEN"); fi

# json_field FIELD: prints a field (a dotted path) of the JSON document on stdin.
json_field() {
  python3 -c '
import json, sys
v = json.load(sys.stdin)
for k in sys.argv[1].split("."):
    v = v.get(k) if isinstance(v, dict) else None
print("" if v is None else (v if isinstance(v, str) else json.dumps(v)))
' "$1"
}

# request METHOD PATH [curl args...]: prints the body to stdout on a 2xx answer; otherwise prints the server's
# problem ("status title: detail at pointer", then each further error of a refused document on a line of its own, and
# what checks are pending) to stderr and exits 1.
request() {
  local method=$1 path=$2
  shift 2
  local body_file status
  body_file=$(mktemp)
  if ! status=$(curl -sS -o "$body_file" -w '%{http_code}' -X "$method" ${TESSERA_AUTH[@]+"${TESSERA_AUTH[@]}"} "$@" "$TESSERA_URL$path"); then
    rm -f "$body_file"
    echo "error: cannot reach $TESSERA_URL: is tesserad running? (\`make run\` in the repository starts it; TESSERA_URL names another)" >&2
    exit 1
  fi
  if [[ $status != 2* ]]; then
    python3 -c '
import json, sys
text = open(sys.argv[1], encoding="utf-8", errors="replace").read()
try:
    p = json.loads(text)
    where = " at " + (p["pointer"] or "/") if "pointer" in p else ""
    print("error: HTTP %s %s: %s%s" % (p.get("status", sys.argv[2]), p.get("title", ""), p.get("detail", ""), where))
    for e in p.get("errors", [])[1:]:
        print("error: %s at %s" % (e.get("detail", ""), e.get("pointer") or "/"))
    if p.get("pending"):
        print("error: " + p["pending"])
except Exception:
    print("error: HTTP %s: %s" % (sys.argv[2], text[:500]))
' "$body_file" "$status" >&2
    rm -f "$body_file"
    exit 1
  fi
  cat "$body_file"
  rm -f "$body_file"
}
