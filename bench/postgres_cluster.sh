# Sourced by the cluster benchmarks (bench/cluster_scaling.sh, bench/frames_cluster.sh): a throw-away PostgreSQL
# (initdb in a temporary directory, a Unix socket, no fsync; as `nobody` when run as root) and tesserad nodes on
# loopback. The caller sets `bench` (its name, for messages) and `tesserad`, and may set `daemon_args` (given to every
# daemon); this file sets `work` (removed at exit, with every daemon and the database server stopped), `bindir`,
# new_database (a fresh database, its URI in $uri), psql_in SQL (in the latest database), start NAME DATA_DIR ARGS...
# (a daemon; its URL in $url, its output in $work/NAME.*) and stop_all.
bindir=${TESSERA_PG_BINDIR:-$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1)}
[[ -x $bindir/initdb ]] || { echo "$bench: no PostgreSQL server programs (apt install postgresql)" >&2; exit 2; }
work=$(mktemp -d)
chmod 755 "$work"
as_pg=()
[[ $(id -u) == 0 ]] && as_pg=(runuser -u nobody --)
pids=()
stop_all() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  pids=()
}
cleanup() {
  stop_all
  [[ -d $work/pg ]] && "${as_pg[@]}" "$bindir/pg_ctl" -D "$work/pg/data" -m immediate -w stop >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

mkdir "$work/pg" && chmod 777 "$work/pg"
"${as_pg[@]}" "$bindir/initdb" -D "$work/pg/data" -U tessera --auth=trust -E UTF8 --locale=C --no-sync >/dev/null
"${as_pg[@]}" "$bindir/pg_ctl" -D "$work/pg/data" -w -l "$work/pg/server.log" \
  -o "-k $work/pg -c listen_addresses= -c fsync=off" start >/dev/null
db=0
new_database() {
  db=$((db + 1))
  "${as_pg[@]}" "$bindir/psql" -h "$work/pg" -U tessera -d postgres -qAtc "CREATE DATABASE bench$db" >/dev/null
  uri="postgresql://tessera@/bench$db?host=$work/pg"
}
psql_in() { "${as_pg[@]}" "$bindir/psql" -h "$work/pg" -U tessera -d "bench$db" -qAtc "$1"; }

start() {
  local name=$1 dir=$2; shift 2
  mkdir -p "$dir"
  : >"$work/$name.out"
  "$tesserad" --listen 127.0.0.1 --port 0 --data-dir "$dir" --grace-s 2 "${daemon_args[@]}" "$@" \
    >"$work/$name.out" 2>"$work/$name.log" &
  pids+=($!)
  url=""
  for _ in $(seq 100); do
    url=$(sed -n 's/.*listening on \(http:[^ ]*\).*/\1/p' "$work/$name.out")
    [[ -n $url ]] && break
    sleep 0.1
  done
  [[ -n $url ]] || { cat "$work/$name.log" >&2; echo "$bench: tesserad did not start" >&2; exit 1; }
  url=${url%/}
}
