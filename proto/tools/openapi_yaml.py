#!/usr/bin/env python3
"""Writes proto/openapi.yaml from proto/openapi.json, the source of truth of the HTTP API.

Usage: openapi_yaml.py openapi.json openapi.yaml          (regenerate)
       openapi_yaml.py --check openapi.json openapi.yaml  (exit 1 when the YAML is out of date)

Standard library only. String values (and unusual keys) are written as JSON strings, which are valid YAML double-quoted scalars, so
the YAML means exactly what the JSON means.
"""
import json
import re
import sys

HEADER = "# Generated from openapi.json by tools/openapi_yaml.py. Do not edit: edit openapi.json and regenerate.\n"


PLAIN_KEY = re.compile(r"^[A-Za-z_$/][A-Za-z0-9_$./{}-]*$")
YAML_WORDS = {"y", "n", "yes", "no", "on", "off", "true", "false", "null"}


def scalar(v):
    return json.dumps(v, ensure_ascii=False)


def key(k):
    # Plain where YAML reads it back as the same string; quoted otherwise.
    return k if PLAIN_KEY.match(k) and k.lower() not in YAML_WORDS else scalar(k)


def emit(value, indent, out):
    pad = "  " * indent
    if isinstance(value, dict):
        for k, v in value.items():
            if isinstance(v, (dict, list)) and v:
                out.append(f"{pad}{key(k)}:")
                emit(v, indent + 1, out)
            else:
                out.append(f"{pad}{key(k)}: {scalar(v) if not isinstance(v, (dict, list)) else ('{}' if isinstance(v, dict) else '[]')}")
    elif isinstance(value, list):
        for v in value:
            if isinstance(v, (dict, list)) and v:
                inner = []
                emit(v, indent + 1, inner)
                # The first line of the item goes after the dash.
                out.append(f"{pad}- {inner[0].lstrip()}")
                out.extend(inner[1:])
            else:
                out.append(f"{pad}- {scalar(v) if not isinstance(v, (dict, list)) else ('{}' if isinstance(v, dict) else '[]')}")
    else:
        out.append(pad + scalar(value))


def render(doc):
    out = []
    emit(doc, 0, out)
    return HEADER + "\n".join(out) + "\n"


def main(argv):
    check = "--check" in argv
    args = [a for a in argv[1:] if a != "--check"]
    if len(args) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    with open(args[0], encoding="utf-8") as f:
        text = render(json.load(f))
    if check:
        try:
            with open(args[1], encoding="utf-8") as f:
                current = f.read()
        except FileNotFoundError:
            current = ""
        if current != text:
            print(f"{args[1]} is out of date: run {argv[0]} {args[0]} {args[1]}", file=sys.stderr)
            return 1
        return 0
    with open(args[1], "w", encoding="utf-8") as f:
        f.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
