#!/usr/bin/env bash
# Runs a Python script with the first python3 that has PyYAML (the one on PATH, else Debian's /usr/bin/python3 with
# python3-yaml); exits 77 (skipped) when none has it.
for py in python3 /usr/bin/python3; do
  if command -v "$py" >/dev/null && "$py" -c 'import yaml' 2>/dev/null; then exec "$py" "$@"; fi
done
echo "SKIPPED: no python3 with PyYAML (Debian package python3-yaml)"
exit 77
