#!/usr/bin/env python3
"""No import cycles between source files (issue 11).

For every crate of the workspace (sim, calib, plot, the CLI in src/), reads each .rs file's `use`
declarations and inline `crate::`/`super::` paths, maps each to the source file of the module it names,
and looks for cycles in that file graph (Tarjan's strongly connected components). The unit-test module
at the end of a file is left out (its `super` is the file itself). A parent module file
(`mod.rs`, `lib.rs`) naming its own children in `mod` declarations is not an import; a child using its
parent's items is. Exits 1 and names the files of every cycle; 0 when there is none.

    python3 scripts/check_import_cycles.py [ROOT]
"""
import os
import re
import sys

ROOT = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), ".."))
CRATES = {"sim": "sim/src", "calib": "calib/src", "plot": "plot/src", "robocal": "src"}

USE_RE = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?use\s+([^;]+);", re.M)
INLINE_RE = re.compile(r"\b(crate|super)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")


def module_files(src):
    """Map from module path (tuple) to file, for one crate's source folder."""
    out = {}
    for dirpath, _, files in os.walk(src):
        for f in files:
            if not f.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(dirpath, f), src)
            parts = rel[:-3].split(os.sep)
            if parts[-1] in ("mod", "lib", "main"):
                parts = parts[:-1]
            out[tuple(parts)] = os.path.join(dirpath, f)
    return out


def strip_comments(text):
    """Comments and the unit-test module (`#[cfg(test)] mod tests`, where `super` is the file itself)."""
    text = re.sub(r"//[^\n]*", "", text)
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    m = re.search(r"#\[cfg\(test\)\]\s*mod\s+\w+\s*\{", text)
    return text[: m.start()] if m else text


def expand(tree):
    """`a::{b, c::{d}}` -> ['a::b', 'a::c::d'] (good enough for use trees)."""
    tree = tree.strip()
    m = re.match(r"^(.*?)::\{(.*)\}$", tree, re.S)
    if not m:
        return [tree]
    prefix, inner = m.group(1), m.group(2)
    items, depth, cur = [], 0, ""
    for ch in inner:
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        if ch == "," and depth == 0:
            items.append(cur)
            cur = ""
        else:
            cur += ch
    items.append(cur)
    out = []
    for it in items:
        it = it.strip()
        if it and it != "self":
            out.extend(prefix + "::" + e for e in expand(it))
        elif it == "self":
            out.append(prefix)
    return out


def target(mods, here, path):
    """The file a `crate::…`/`super::…` path names, from module `here` (tuple)."""
    segs = path.split("::")
    if segs[0] == "crate":
        base, rest = (), segs[1:]
    elif segs[0] == "super":
        base, rest = here, segs
        while rest and rest[0] == "super":
            base, rest = base[:-1], rest[1:]
    elif segs[0] == "self":
        base, rest = here, segs[1:]
    else:
        return None
    best = None
    for k in range(len(rest) + 1):
        key = base + tuple(rest[:k])
        if key in mods:
            best = mods[key]
    return best


def graph(crate_src):
    mods = module_files(crate_src)
    by_file = {f: m for m, f in mods.items()}
    edges = {f: set() for f in by_file}
    for f, here in by_file.items():
        # A file's own module for `super`: its parent module.
        parent = here[:-1] if not f.endswith(("mod.rs", "lib.rs", "main.rs")) else here[:-1]
        own = here if f.endswith(("mod.rs", "lib.rs", "main.rs")) else here
        text = strip_comments(open(f, encoding="utf-8").read())
        paths = []
        for m in USE_RE.finditer(text):
            paths.extend(expand(m.group(1)))
        for m in INLINE_RE.finditer(text):
            paths.append(m.group(1) + m.group(2))
        for p in paths:
            p = p.split(" as ")[0].strip()
            if p.startswith("super"):
                t = target(mods, own, p)
            else:
                t = target(mods, own, p)
            if t and t != f:
                # A parent naming its child (re-exports, `mod` items) is not an import of the child's
                # parent; a child naming its parent is.
                tm = by_file[t]
                if tm[: len(here)] == here and len(tm) > len(here):
                    continue
                edges[f].add(t)
        _ = parent
    return edges


def cycles(edges):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in edges:
        if v not in index:
            strong(v)
    return out


def main():
    bad = 0
    for crate, src in CRATES.items():
        src = os.path.join(ROOT, src)
        if not os.path.isdir(src):
            continue
        for comp in cycles(graph(src)):
            bad += 1
            rel = [os.path.relpath(f, ROOT) for f in comp]
            print(f"import cycle in {crate}: " + " <-> ".join(rel))
    if bad:
        sys.exit(1)
    print("no import cycles between source files")


if __name__ == "__main__":
    main()
