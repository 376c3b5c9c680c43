#!/usr/bin/env bash
# The .deb on a clean Debian 12, for real: makes the package with cpack, installs it with apt in a fresh
# debian:bookworm container (so Depends must resolve from Debian alone), and checks what the maintainer scripts do:
# the `tessera` system user, /var/lib/tessera (tessera:tessera 0750), the settings file readable by the group;
# a reinstall (postinst again) changes nothing; the installed tesserad, run as `tessera` with the unit's command
# line, answers /readyz and stops on SIGTERM; `apt remove` keeps the data, `apt purge` removes it.
#   deb_container_test.sh SOURCE_DIR BUILD_DIR
# Exit 0 passed, 1 failed, 77 skipped (see podman_env.sh).
set -uo pipefail
test_name=deb_container_test
# shellcheck source-path=SCRIPTDIR source=podman_env.sh
source "$(dirname "$0")/podman_env.sh"

command -v cpack >/dev/null || skip "cpack is not installed"
mkdir -p "$work/pkg"
if ! (cd "$build" && cpack -G DEB -B "$work/out" --config "$build/CPackConfig.cmake") >"$work/cpack.log" 2>&1; then
  cat "$work/cpack.log"; fail "cpack -G DEB failed"
fi
cp "$work"/out/*.deb "$work/pkg/" || fail "cpack made no .deb"
say "installing $(basename "$work"/pkg/*.deb) in a fresh $base"

name=$tag-deb
containers+=("$name")
# shellcheck disable=SC2016  # the script runs inside the container
timeout 900 podman run --name "$name" -v "$work/pkg:/pkg:ro" "$base" /bin/bash -c '
set -euo pipefail
ok() { echo "ok   $*"; }
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends /pkg/tessera_*.deb curl >/tmp/apt.log 2>&1 || { tail -20 /tmp/apt.log; exit 1; }
ok "apt-get install ./tessera_*.deb: Depends resolve on a clean bookworm"
check_state() {
  grep -q ":/var/lib/tessera:/usr/sbin/nologin$" <<<"$(getent passwd tessera)"
  [ "$(id -u tessera)" -lt 1000 ]
  [ "$(stat -c %U:%G:%a /var/lib/tessera)" = tessera:tessera:750 ]
  [ "$(stat -c %U:%G:%a /etc/tessera/tesserad.env)" = root:tessera:640 ]
  [ "$(stat -c %U:%G:%a /etc/tessera/tesserad.json)" = root:tessera:640 ]
}
check_state && ok "postinst: system user tessera, /var/lib/tessera tessera:tessera 0750, /etc/tessera/* root:tessera 0640"
touch /var/lib/tessera/keep
dpkg -i /pkg/tessera_*.deb >/dev/null
check_state && [ -f /var/lib/tessera/keep ] && [ "$(getent passwd | grep -c ^tessera:)" = 1 ]
ok "reinstall: postinst again, same user, data untouched"
[ "$(dpkg-query -W -f="\${Conffiles}" tessera | awk "NF {print \$1}" | sort | tr "\n" " ")" = "/etc/tessera/tesserad.env /etc/tessera/tesserad.json " ]
ok "dpkg knows /etc/tessera/tesserad.json and tesserad.env as conffiles"
# The unit'"'"'s command line and environment, as the unit'"'"'s user.
set -a
eval "$(sed -n "s/^Environment=//p" /lib/systemd/system/tesserad.service)"
. /etc/tessera/tesserad.env
set +a
[ "$TESSERA_CONFIG" = /etc/tessera/tesserad.json ]
exec_start=$(sed -n "s/^ExecStart=//p" /lib/systemd/system/tesserad.service)
setpriv --reuid=tessera --regid=tessera --init-groups -- $exec_start --port 18080 >/tmp/tesserad.out 2>/tmp/tesserad.err &
pid=$!
for i in $(seq 1 100); do curl -fsS -m 2 -o /dev/null http://127.0.0.1:18080/readyz 2>/dev/null && break; sleep 0.2; done
curl -fsS -m 2 http://127.0.0.1:18080/readyz >/dev/null || { cat /tmp/tesserad.out /tmp/tesserad.err; exit 1; }
grep -q "listening on http://127.0.0.1:18080" /tmp/tesserad.out
[ -f /var/lib/tessera/jobs.db ] && [ "$(stat -c %U /var/lib/tessera/jobs.db)" = tessera ]
ok "the installed tesserad runs as tessera: 127.0.0.1:18080 ready, jobs.db in /var/lib/tessera"
kill -TERM $pid; status=0; wait $pid || status=$?
[ $status -eq 0 ]
ok "SIGTERM: tesserad exits 0"
apt-get remove -y -qq tessera >/dev/null 2>&1
[ ! -e /usr/bin/tesserad ] && [ -f /var/lib/tessera/jobs.db ] && [ -f /etc/tessera/tesserad.json ]
ok "apt remove: binaries gone, data and settings kept"
apt-get purge -y -qq tessera >/dev/null 2>&1
[ ! -e /var/lib/tessera ] && [ ! -e /etc/tessera/tesserad.json ] && [ ! -e /etc/tessera/tesserad.env ]
ok "apt purge: data and settings gone"
' 2>"$work/podman.err"
status=$?
[ $status -eq 0 ] || { tail -n 5 "$work/podman.err"; fail "the .deb checks in the container failed (status $status)"; }
say "all checks passed"
