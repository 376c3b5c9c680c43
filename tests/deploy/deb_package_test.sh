#!/usr/bin/env bash
# The Debian package: runs `cpack -G DEB` in the build tree, then checks the package with dpkg-deb: its control fields
# (-I/-f), its maintainer scripts, and its layout unpacked into a scratch root (-x); runs the unpacked tesserad and
# checks the unpacked unit with systemd_unit_test.sh.
#   deb_package_test.sh SOURCE_DIR BUILD_DIR
# Exit 0 passed, 1 failed, 77 skipped (no cpack or dpkg-deb).
set -uo pipefail
src=$(cd "${1:?usage: deb_package_test.sh SOURCE_DIR BUILD_DIR}" && pwd)
build=$(cd "${2:?usage: deb_package_test.sh SOURCE_DIR BUILD_DIR}" && pwd)
for tool in cpack dpkg-deb dpkg-shlibdeps; do
  command -v $tool >/dev/null || { echo "SKIPPED: $tool is not installed"; exit 77; }
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failed=0
check() {  # CONDITION-STATUS WHAT
  if [ "$1" -eq 0 ]; then echo "ok   $2"; else echo "FAIL $2"; failed=1; fi
}

(cd "$build" && cpack -G DEB -B "$work/out" --config "$build/CPackConfig.cmake") >"$work/cpack.log" 2>&1
rc=$?
debs=("$work"/out/*.deb)
if [ $rc -ne 0 ] || [ ! -f "${debs[0]}" ]; then cat "$work/cpack.log"; echo "FAIL cpack -G DEB (status $rc)"; exit 1; fi
deb=${debs[0]}
version=$(sed -nE 's/^project\(tessera VERSION ([0-9.]+).*/\1/p' "$src/CMakeLists.txt")
echo "cpack: $(basename "$deb"), $(stat -c %s "$deb") bytes"
dpkg-deb -I "$deb" | sed 's/^/  /'

field() { dpkg-deb -f "$deb" "$1"; }
[ "$(field Package)" = tessera ]; check $? "Package: tessera"
[ "$(field Version)" = "$version" ]; check $? "Version: $version (the project's)"
[ "$(basename "$deb")" = "tessera_${version}_$(dpkg --print-architecture).deb" ]; check $? "file name tessera_VERSION_ARCH.deb"
[ -n "$(field Maintainer)" ] && [ -n "$(field Description)" ]; check $? "Maintainer and Description"
depends=$(field Depends)
[ -n "$depends" ]; check $? "Depends is not empty"
for lib in libembree3-3 libopenimageio2.4 libcpp-httplib0.11 libsqlite3-0 passwd; do
  [[ ", $depends," == *", $lib"[\ ,]* ]]; check $? "Depends names $lib"
done

dpkg-deb -e "$deb" "$work/control"
for script in postinst prerm postrm; do
  [ -x "$work/control/$script" ] && sh -n "$work/control/$script"; check $? "$script: present, executable, valid sh"
done
grep -q 'useradd --system' "$work/control/postinst" && grep -q '/var/lib/tessera' "$work/control/postinst"
check $? "postinst creates the tessera system user and /var/lib/tessera"
[ "$(sort "$work/control/conffiles" | tr '\n' ' ')" = "/etc/tessera/tesserad.env /etc/tessera/tesserad.json " ]
check $? "conffiles: /etc/tessera/tesserad.json and tesserad.env"

root=$work/root
dpkg-deb -x "$deb" "$root"
for f in usr/bin/tesserad usr/bin/tessera usr/bin/tessera-render; do
  [ -x "$root/$f" ]; check $? "/$f"
done
for f in usr/share/tessera/web/index.html lib/systemd/system/tesserad.service etc/tessera/tesserad.json \
         etc/tessera/tesserad.env; do
  [ -f "$root/$f" ]; check $? "/$f"
done
web_src=$(cd "$src/clients/web" && find . -type f | sort)
web_deb=$(cd "$root/usr/share/tessera/web" && find . -type f | sort)
[ "$web_src" = "$web_deb" ]; check $? "/usr/share/tessera/web holds every file of clients/web"
stray=$(cd "$root" && find . -type f | grep -vE '^\./(usr/bin/tessera|usr/bin/tessera-render|usr/bin/tesserad|usr/share/tessera/web/.*|lib/systemd/system/tesserad\.service|etc/tessera/tesserad\.(json|env))$')
[ -z "$stray" ]; check $? "no other files in the package${stray:+: $stray}"
cmp -s "$root/lib/systemd/system/tesserad.service" "$src/deploy/systemd/tesserad.service"; check $? "the unit is deploy/systemd/tesserad.service"
grep -q -- '--data-dir' <<<"$("$root/usr/bin/tesserad" --help)"; check $? "the unpacked tesserad runs (--help)"
env -u TESSERA_CONFIG "$root/usr/bin/tesserad" --config "$root/etc/tessera/tesserad.json" --help >/dev/null
check $? "the unpacked tesserad accepts the packaged /etc/tessera/tesserad.json"
"$root/usr/bin/tessera" --help >/dev/null 2>&1 || grep -qi usage <<<"$("$root/usr/bin/tessera" 2>&1)"; check $? "the unpacked tessera runs"

status=0
"$src/tests/deploy/systemd_unit_test.sh" "$root/lib/systemd/system/tesserad.service" "$root/usr/bin/tesserad" || status=$?
[ $status -eq 0 ] || [ $status -eq 77 ]; check $? "the packaged unit passes systemd_unit_test.sh with the packaged tesserad"

if [ $failed -ne 0 ]; then exit 1; fi
echo "deb package checks passed"
