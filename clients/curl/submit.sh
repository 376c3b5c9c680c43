#!/usr/bin/env bash
# Submits a job to tesserad and prints the new job's id: a JSON job document, or a glTF scene uploaded as
# multipart/form-data (a .glb; or a .gltf with its .bin and image files), optionally with a job document for it.
set -euo pipefail
usage() {
  cat <<'USAGE'
usage: submit.sh JOB.json                 submit a job document (- reads stdin)
       submit.sh JOB.json FILE...         the job plus files it names (multipart: "gltf" names an uploaded file)
       submit.sh SCENE.glb|SCENE.gltf [FILE...]   render a glTF asset with default settings (multipart)
prints the job id; TESSERA_URL (default http://127.0.0.1:8080), TESSERA_TOKEN (bearer token, optional)
USAGE
}
if [[ ${1:-} == -h || ${1:-} == --help ]]; then usage; exit 0; fi
if [[ $# -lt 1 ]]; then usage >&2; exit 2; fi
for f in "$@"; do
  [[ $f == - || -r $f ]] || { echo "error: cannot read $f" >&2; exit 2; }
done
source "$(dirname "$0")/common.sh"
if [[ $# -eq 1 && ! $1 =~ \.(glb|gltf|GLB|GLTF)$ ]]; then
  job=$(request POST /v1/jobs -H 'Content-Type: application/json' --data-binary "@$1")
else
  doc=$1
  if [[ $1 =~ \.(glb|gltf|GLB|GLTF)$ ]]; then
    # A bare asset: a scene job that names it.
    doc=$(mktemp)
    trap 'rm -f "$doc"' EXIT
    printf '{"kind": "scene", "scene": {"gltf": "%s"}}\n' "$(basename "$1")" >"$doc"
  else
    shift
  fi
  parts=(-F "job=@$doc;type=application/json;filename=job.json")
  for f in "$@"; do parts+=(-F "file=@$f;filename=$(basename "$f")"); done
  job=$(request POST /v1/jobs "${parts[@]}")
fi
json_field id <<<"$job"
