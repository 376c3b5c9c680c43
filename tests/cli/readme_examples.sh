#!/usr/bin/env bash
# The README's examples run as written from a clone: every `sh` block of the sections a user follows with a built
# tree and a running daemon (A first render, The HTTP API, the command line's render-farm example, glTF scenes,
# Materials; their subsections included) runs, in order, in one shell with `set -e`, in a copy of the repository's
# tracked files whose build/ is this build, against a tesserad on a free port (the README's http://127.0.0.1:8080 is
# replaced by its address).
# Synopses (lines that start with a bare `tessera `) are not commands and are skipped; so are the sections that
# install, deploy or benchmark (the deploy and container tests run those). The sample assets must come out unchanged,
# and `git status` clean: the examples write their outputs where .gitignore keeps them out of the way (the copy is a
# repository of its own, with the tracked files committed, to ask git).
# usage: readme_examples.sh BUILD_DIR     (run by CTest)
set -uo pipefail
build=${1:?usage: readme_examples.sh BUILD_DIR}
build=$(cd "$build" && pwd)
repo=$(cd "$(dirname "$0")/../.." && pwd)
git -C "$repo" rev-parse --is-inside-work-tree >/dev/null 2>&1 || { echo "not a git checkout: skipped"; exit 77; }
tmp=$(mktemp -d)
daemon_pid=""
cleanup() {
  if [[ -n $daemon_pid ]]; then kill -TERM "$daemon_pid" 2>/dev/null; wait "$daemon_pid" 2>/dev/null; fi
  rm -rf "$tmp"
}
trap cleanup EXIT

# A clone's files: what git tracks (as they are in the working tree), and this build as build/.
mkdir -p "$tmp/clone"
(cd "$repo" && git ls-files -z --cached --others --exclude-standard | tar --null -T - -cf -) | tar -C "$tmp/clone" -xf -
ln -s "$build" "$tmp/clone/build"
(
  cd "$tmp/clone" && git init -q && echo /build >>.git/info/exclude && git add -A &&
    git -c user.name=readme -c user.email=readme@localhost commit -qm "the tracked files"
) || { echo "cannot make the copy a git repository"; exit 1; }
[[ -z $(git -C "$tmp/clone" status --porcelain) ]] || { echo "the copy is not clean before the examples"; exit 1; }
assets_before=$(cd "$tmp/clone" && find examples -type f -print0 | sort -z | xargs -0 sha256sum)

"$build/server/tesserad" --port 0 --listen 127.0.0.1 --data-dir "$tmp/data" --threads 2 --log-level warn \
  >"$tmp/daemon.out" 2>"$tmp/daemon.err" &
daemon_pid=$!
url=""
for _ in $(seq 100); do
  url=$(sed -n 's/.*listening on \(http:[^ ]*\).*/\1/p' "$tmp/daemon.out" | head -1)
  [[ -n $url ]] && break
  sleep 0.1
done
[[ -n $url ]] || { echo "tesserad did not start"; cat "$tmp/daemon.err"; exit 1; }
url=${url%/}

# The blocks, in README order, from the sections named above.
python3 - "$repo/README.md" "$url" >"$tmp/examples.sh" <<'PY'
import re, sys
text = open(sys.argv[1]).read().replace("http://127.0.0.1:8080", sys.argv[2])
sections = ("## A first render", "## The HTTP API", "## Web client, command line, curl", "## glTF scenes",
            "## Materials")
heading, block, out = "", None, []
for line in text.split("\n"):
    if block is None and line.startswith("## "):
        heading = line.strip()
    elif block is None and line.startswith("```sh"):
        block = []
    elif block is not None and line.startswith("```"):
        if heading in sections and not any(l.startswith("tessera ") for l in block):
            out.append(f"echo '### README: {heading[3:]}'\n" + "\n".join(block))
        block = None
    elif block is not None:
        block.append(line)
print("set -euo pipefail\n" + "\n".join(out))
PY
blocks=$(grep -c "^echo '### README" "$tmp/examples.sh")
echo "running $blocks README blocks against $url"
failed=0
if ! (cd "$tmp/clone" && TESSERA_URL=$url bash -x "$tmp/examples.sh") >"$tmp/run.out" 2>"$tmp/run.err"; then
  echo "not ok - a README example failed:"
  tail -30 "$tmp/run.err"
  failed=1
else
  echo "ok - $blocks README blocks ran"
fi
[[ $blocks -ge 6 ]] && echo "ok - every section's examples were found" || { echo "not ok - only $blocks blocks"; failed=1; }
for f in out/result.png out/result.exr out/preview.png out/cornell.png out/quick.png out/duck.png out/prism.png \
  out/merged.exr out/merged.png; do
  [[ -s $tmp/clone/$f ]] && echo "ok - the examples wrote $f" || { echo "not ok - no $f"; failed=1; }
done
assets_after=$(cd "$tmp/clone" && find examples -type f -print0 | sort -z | xargs -0 sha256sum)
[[ $assets_before == "$assets_after" ]] && echo "ok - examples/ is unchanged" || { echo "not ok - examples/ changed"; failed=1; }
untracked=$(git -C "$tmp/clone" status --porcelain)
[[ -z $untracked ]] && echo "ok - git status is clean after the examples" \
  || { echo "not ok - the examples left files git sees:"; echo "$untracked" | sed 's/^/    /'; failed=1; }
exit $failed
