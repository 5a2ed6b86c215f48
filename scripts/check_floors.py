#!/usr/bin/env python3
"""No import runs back up a floor (issue 23).

Each crate's top-level modules are arranged in floors, listed bottom to top below. A source file may
import (`use`, or an inline `crate::`/`super::` path, as `check_import_cycles.py` reads them) only
modules of its own floor or of floors below it. Exits 1 and names every file and import that reaches
up; 0 when there is none.

    python3 scripts/check_floors.py [ROOT]

A new top-level module must be given its floor here, or the check fails naming it.
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import check_import_cycles as cycles  # noqa: E402

FLOORS = {
    "calib": [
        # ground: numbers, errors, the solver
        ["lib", "error", "cancel", "units", "linalg", "lie3", "health", "lm", "io", "part"],
        ["model"],
        ["fit"],
        ["validate"],
        ["select"],
    ],
}


def top(src, path):
    rel = os.path.relpath(path, src).split(os.sep)[0]
    return rel[:-3] if rel.endswith(".rs") else rel


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, ".."))
    cycles.ROOT = root
    bad = 0
    for crate, floors in FLOORS.items():
        src = os.path.join(root, cycles.CRATES[crate])
        level = {m: k for k, names in enumerate(floors) for m in names}
        edges = cycles.graph(src)
        for f in sorted(edges):
            a = top(src, f)
            if a not in level:
                print(f"{crate}: module '{a}' ({os.path.relpath(f, root)}) has no floor in scripts/check_floors.py")
                bad += 1
                continue
            for t in sorted(edges[f]):
                b = top(src, t)
                if b == "lib":
                    continue
                if b not in level:
                    continue  # reported above for its own files
                if level[b] > level[a]:
                    print(
                        f"{crate}: {os.path.relpath(f, root)} (floor {a}) imports "
                        f"{os.path.relpath(t, root)} (floor {b}), which is above it"
                    )
                    bad += 1
    if bad:
        sys.exit(1)
    print("no import runs back up a floor")


if __name__ == "__main__":
    main()
