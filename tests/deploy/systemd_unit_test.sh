#!/usr/bin/env bash
# Checks a tesserad systemd unit with systemd's own tools:
#   systemd-analyze verify        no error and no warning about the unit (a broken copy must draw one: self-check)
#   systemd-analyze security      offline exposure score at most 2.5 ("OK")
#   systemd_unit_test.sh UNIT_FILE TESSERAD_BINARY
# verify needs ExecStart's program to exist, so it checks a copy of the unit whose ExecStart names TESSERAD_BINARY
# (the freshly built one, or the one unpacked from the .deb). Exit 0 passed, 1 failed, 77 skipped (no systemd-analyze).
set -uo pipefail
unit=${1:?usage: systemd_unit_test.sh UNIT_FILE TESSERAD_BINARY}
binary=$(readlink -f "${2:?usage: systemd_unit_test.sh UNIT_FILE TESSERAD_BINARY}")
command -v systemd-analyze >/dev/null || { echo "SKIPPED: systemd-analyze is not installed (Debian package systemd)"; exit 77; }
[ -x "$binary" ] || { echo "FAIL: $binary is not an executable"; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failed=0

copy=$work/tesserad.service
sed -E "s|^ExecStart=/usr/bin/tesserad|ExecStart=$binary|" "$unit" >"$copy"
grep -q "^ExecStart=$binary " "$copy" || { echo "FAIL: no ExecStart=/usr/bin/tesserad in $unit"; exit 1; }

verify() {  # FILE -> prints the lines about FILE's unit; returns systemd-analyze's status
  local out rc
  out=$(SYSTEMD_LOG_COLOR=0 systemd-analyze verify "$1" 2>&1); rc=$?
  # Lines about other units of this machine are not ours to judge; nor is a missing user `tessera` (the .deb makes it).
  printf '%s\n' "$out" | grep -F "$(basename "$1")" | grep -viE "(resolve|unknown|no such) user" || true
  return $rc
}

lines=$(verify "$copy"); rc=$?
if [ $rc -ne 0 ] || [ -n "$lines" ]; then
  echo "FAIL: systemd-analyze verify (status $rc):"; printf '%s\n' "$lines"; failed=1
else
  echo "ok   systemd-analyze verify $(basename "$unit"): no errors, no warnings"
fi

# Self-check: the same unit with a misspelt key and a bad value must draw warnings.
broken=$work/broken/tesserad.service
mkdir -p "$(dirname "$broken")"
sed -e 's/^ProtectSystem=strict/ProtectSystem=very-strict\nProtectSistem=yes/' "$copy" >"$broken"
if [ -z "$(verify "$broken")" ]; then
  echo "FAIL: systemd-analyze verify did not notice a broken copy of the unit"; failed=1
else
  echo "ok   systemd-analyze verify notices a broken copy"
fi

out=$(SYSTEMD_LOG_COLOR=0 systemd-analyze security --offline=yes --threshold=25 "$copy" 2>&1); rc=$?
score=$(printf '%s\n' "$out" | grep -o 'Overall exposure level.*' | head -n 1)
if [ $rc -ne 0 ] || [ -z "$score" ]; then
  printf '%s\n' "$out" | grep -E '^✗' | head -n 20
  echo "FAIL: systemd-analyze security (status $rc): ${score:-no score}"; failed=1
else
  echo "ok   systemd-analyze security: ${score#Overall exposure level for }"
fi

if [ $failed -ne 0 ]; then exit 1; fi
echo "systemd unit checks passed"
