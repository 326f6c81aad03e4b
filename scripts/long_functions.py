#!/usr/bin/env python3
"""Functions longer than a limit (default 150 lines) in src/, by brace matching from each
`fn` signature to its closing brace. Comments and strings are not parsed, so braces inside
string literals can mislead it; it is a reviewer's aid, not a proof.

usage: python3 scripts/long_functions.py [LIMIT]
"""
import os
import re
import sys

limit = int(sys.argv[1]) if len(sys.argv) > 1 else 150
fn_re = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?fn\s+(\w+)")
found = 0
for root, _, files in os.walk("src"):
    for name in sorted(files):
        if not name.endswith(".rs"):
            continue
        path = os.path.join(root, name)
        lines = open(path, encoding="utf-8").read().split("\n")
        for i, line in enumerate(lines):
            m = fn_re.match(line)
            if not m:
                continue
            depth, opened = 0, False
            for j in range(i, len(lines)):
                code = lines[j].split("//")[0]
                depth += code.count("{") - code.count("}")
                if "{" in code:
                    opened = True
                if opened and depth <= 0:
                    break
                if not opened and code.rstrip().endswith(";"):
                    break
            length = j - i + 1
            if opened and length > limit:
                found += 1
                print(f"{path}:{i + 1}: fn {m.group(6)} is {length} lines")
print(f"{found} function(s) over {limit} lines")
sys.exit(1 if found else 0)
