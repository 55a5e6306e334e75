#!/usr/bin/env python3
"""File-level import circles inside each crate of the workspace.

A file A "imports" file B when A names a path `crate::…` (or `super::…`) that
resolves to B's module. Prints every strongly connected group of two or more
files, per crate, and the count; exits 0 either way (a report, not a check,
unless --fail is given).

    python3 scripts/import_cycles.py [--fail]
"""
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent


def crate_dirs():
    for toml in sorted(ROOT.glob("*/Cargo.toml")):
        if (toml.parent / "src").is_dir():
            yield toml.parent / "src"
    yield ROOT / "src"


def module_of(src, path):
    rel = path.relative_to(src).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return tuple(parts)


PATH_RE = re.compile(r"\b(crate|super)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")
GROUP_RE = re.compile(r"\b(crate|super)::\{([^}]*)\}")


def targets(mod, text, modules):
    found = set()
    refs = []
    for m in PATH_RE.finditer(text):
        refs.append((m.group(1), [p for p in m.group(2).split("::") if p]))
    for m in GROUP_RE.finditer(text):
        for item in m.group(2).split(","):
            first = item.strip().split("::")[0].strip()
            if first and first != "self":
                refs.append((m.group(1), [p.strip() for p in item.strip().split("::")]))
    for kind, parts in refs:
        base = () if kind == "crate" else mod[:-1]
        full = base + tuple(parts)
        for n in range(len(full), 0, -1):
            if full[:n] in modules:
                if full[:n] != mod and not mod[: n] == full[:n]:
                    found.add(full[:n])
                break
    return found


def sccs(graph):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
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
            out.append(comp)

    sys.setrecursionlimit(10000)
    for v in graph:
        if v not in index:
            visit(v)
    return out


def main():
    total = 0
    for src in crate_dirs():
        files = {module_of(src, p): p for p in src.rglob("*.rs")}
        graph = {}
        for mod, path in files.items():
            text = re.sub(r"//[^\n]*", "", path.read_text())
            # Tests inside a file (`#[cfg(test)] mod tests`) use their parent freely.
            text = text.split("#[cfg(test)]")[0]
            graph[mod] = targets(mod, text, files)
        for comp in sccs(graph):
            if len(comp) > 1:
                total += 1
                names = sorted(str(files[m].relative_to(ROOT)) for m in comp)
                print(f"{src.parent.name or 'nelf'}: " + " <-> ".join(names))
    print(f"{total} file-level import circle(s)")
    if "--fail" in sys.argv and total:
        sys.exit(1)


if __name__ == "__main__":
    main()
