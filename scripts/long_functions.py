#!/usr/bin/env python3
"""Lists the functions longer than LIMIT lines (default 60, STYLE.md point 12) in the non-test
C++ sources of the given folders (default: engine api server storage); exits 1 when there are any.

  scripts/long_functions.py [LIMIT] [FOLDER...]

A heuristic, not a parser: a body ends at a '}' in column 0 and starts at the first line in
column 0 after the previous one that is not a comment, a preprocessor line, a namespace or a
declaration ending in ';'. Functions defined inside a class body are not seen."""
import subprocess
import sys

limit = int(sys.argv[1]) if len(sys.argv) > 1 else 60
folders = sys.argv[2:] or ["engine", "api", "server", "storage"]
files = subprocess.run(["git", "ls-files", *folders], capture_output=True, text=True,
                       check=True).stdout.split()
found = 0
for path in files:
    if not path.endswith(".cc") or path.endswith("_test.cc"):
        continue
    start = None
    with open(path, encoding="utf-8") as source:
        for number, line in enumerate(source.read().split("\n"), 1):
            if start is None:
                if line and not line[0].isspace() and \
                   not line.startswith(("//", "#", "}", "namespace", "using")) and \
                   not line.rstrip().endswith(";"):
                    start = (number, line)
            elif line.startswith("}"):
                length = number - start[0] + 1
                is_data = start[1].startswith(
                    ("class", "struct", "const ", "constexpr", "static const"))
                if length > limit and not is_data:
                    print(f"{length:4d} {path}:{start[0]} {start[1].strip()[:90]}")
                    found += 1
                start = None
sys.exit(1 if found else 0)
