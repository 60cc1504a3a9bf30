#!/usr/bin/env python3
"""No import circles between the files of a crate.

Every `.rs` file under each crate's `src/` is a node; a file that names an item of another
file's module (`use crate::a::b`, `super::x`, `crate::a::f(...)` in code, tests included) is an
edge to it. Items re-exported by `lib.rs` or a `mod.rs` (`pub use x::Item`) count as the file
that defines them; the `mod x;` declarations of a parent are structure, not edges. Prints the
circles (strongly connected components of two or more files) and exits 1 if there is any.

Usage: tests/module_cycles.py [CRATE_DIR ...]   (default: every crate of the workspace)
"""

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PATH = re.compile(r"\b(crate|super|self)((?:::[A-Za-z_][A-Za-z0-9_]*)+)")
USE = re.compile(r"\buse\s+([^;]+);", re.S)


def strip_comments(text):
    """The code of a file: comments and string literals blanked (lines kept)."""
    out = []
    for line in text.split("\n"):
        s = line.lstrip()
        if s.startswith("//"):
            out.append("")
            continue
        line = re.sub(r'"(?:[^"\\]|\\.)*"', '""', line)
        # `pub(in crate::x)` names a scope, not something used.
        line = re.sub(r"pub\(in [^)]*\)", "pub", line)
        i = line.find("//")
        out.append(line if i < 0 else line[:i])
    return "\n".join(out)


def expand_use(tree):
    """`a::{b, c::{d, e}}` -> ['a::b', 'a::c::d', 'a::c::e']."""
    tree = re.sub(r"\s+", "", tree)
    i = tree.find("{")
    if i < 0:
        return [re.sub(r"\bas\b.*$", "", tree)]
    prefix, inner = tree[:i], tree[i + 1 : tree.rfind("}")]
    parts, depth, cur = [], 0, ""
    for ch in inner:
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
            continue
        depth += ch == "{"
        depth -= ch == "}"
        cur += ch
    parts.append(cur)
    out = []
    for p in parts:
        if p:
            out += [prefix + q for q in expand_use(p)]
    return out


def modules(src):
    """Module path (tuple) -> file, for every file under `src`."""
    mods = {}
    for f in sorted(src.rglob("*.rs")):
        rel = f.relative_to(src).with_suffix("").parts
        if rel in (("lib",), ("main",)):
            key = ()
        elif rel[0] == "bin":
            continue  # binaries are crates of their own
        elif rel[-1] == "mod":
            key = rel[:-1]
        else:
            key = rel
        mods[key] = f
    return mods


def reexports(code):
    """Names a module file re-exports: name -> relative module path of its origin."""
    out = {}
    for m in USE.finditer(code):
        start = code.rfind("\n", 0, m.start()) + 1
        if not code[start : m.start()].strip().startswith("pub"):
            continue
        for p in expand_use(m.group(1)):
            segs = p.split("::")
            out[segs[-1]] = segs[:-1]
    return out


def crate_cycles(crate):
    src = crate / "src"
    mods = modules(src)
    codes = {k: strip_comments(f.read_text()) for k, f in mods.items()}
    exported = {k: reexports(c) for k, c in codes.items()}

    def absolute_path(mod, segs):
        """`segs` (starting with crate / super / self) as a path from the crate root."""
        path = list(mod)
        if segs[0] == "crate":
            path, segs = [], segs[1:]
        while segs and segs[0] in ("super", "self"):
            if segs[0] == "super":
                if not path:
                    return None
                path.pop()
            segs = segs[1:]
        return path + segs

    def resolve(mod, segs):
        """The module (key of `mods`) that defines the item at `segs`, relative to `mod`."""
        path = list(mod)
        if segs[0] == "crate":
            path = []
            segs = segs[1:]
        while segs and segs[0] in ("super", "self"):
            if segs[0] == "super" and path:
                path.pop()
            segs = segs[1:]
        full = path + segs
        # The longest prefix that is a module file.
        for n in range(len(full), -1, -1):
            key = tuple(full[:n])
            if key in mods:
                rest = full[n:]
                # An item re-exported by this module: follow it (once is enough here).
                if rest and rest[0] in exported.get(key, {}):
                    origin = exported[key][rest[0]]
                    sub = tuple(list(key) + [s for s in origin if s not in ("self",)])
                    if origin and origin[0] in ("crate", "super"):
                        return resolve(key, origin + [rest[0]])
                    for m in range(len(sub), len(key), -1):
                        if sub[:m] in mods:
                            return sub[:m]
                return key
        return None

    edges = {k: {} for k in mods}
    for key, code in codes.items():
        lines = code.split("\n")
        test_from = next(
            (i for i, l in enumerate(lines) if re.match(r"\s*(pub(\([^)]*\))?\s+)?mod tests\s*\{", l)),
            len(lines),
        )
        refs = []
        for m in USE.finditer(code):
            line = code.count("\n", 0, m.start())
            start = code.rfind("\n", 0, m.start()) + 1
            public = code[start : m.start()].strip().startswith("pub")
            for p in expand_use(m.group(1)):
                segs = p.split("::")
                if segs[0] not in ("crate", "super", "self"):
                    segs = ["self"] + segs
                refs.append((line, segs, public))
        for m in PATH.finditer(code):
            line = code.count("\n", 0, m.start())
            refs.append((line, [m.group(1)] + m.group(2).split("::")[1:], False))
        # Modules brought into scope by `use` (`use crate::fast::{self, ..}`, `use super::x`):
        # their paths in code (`fast::ops::f()`) are references too.
        aliases = {}
        for line, segs, _ in list(refs):
            if segs[0] not in ("crate", "super", "self") or line > test_from:
                continue
            names = segs[:-1] if segs[-1] == "self" else segs
            absolute = absolute_path(key, names)
            if absolute is not None and tuple(absolute) in mods and len(names) > 1:
                aliases[names[-1]] = absolute
        # A module's children by their relative names (`use walk::Worker`, `obj::read(..)`).
        for child in {k[len(key)] for k in mods if len(k) > len(key) and k[: len(key)] == key}:
            aliases.setdefault(child, list(key) + [child])
        # (`use` statements were read above.)
        bare = USE.sub(lambda m: "\n" * m.group(0).count("\n"), code)
        for name, absolute in aliases.items():
            for m in re.finditer(r"(?<![:\w])" + name + r"((?:::[A-Za-z_][A-Za-z0-9_]*)+)", bare):
                line = bare.count("\n", 0, m.start())
                refs.append((line, ["crate"] + list(absolute) + m.group(1).split("::")[1:], False))
        for line, segs, public in refs:
            if segs[0] not in ("crate", "super", "self"):
                continue
            here = key
            # Inside the file's `mod tests`, `super` is the file itself.
            if line > test_from and segs[0] == "super":
                segs = ["self"] + segs[1:]
            target = resolve(here, segs)
            if target is not None and target != key:
                # A parent's `pub use child::X` is structure, like its `mod child;`.
                if public and target[: len(key)] == key and len(target) > len(key):
                    continue
                edges[key].setdefault(target, line + 1)

    # Tarjan's strongly connected components.
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
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
            if len(comp) > 1:
                comps.append(comp)

    sys.setrecursionlimit(10000)
    for v in list(edges):
        if v not in index:
            visit(v)
    name = lambda k: str(mods[k].relative_to(crate.parent))
    out = []
    for c in comps:
        inside = set(c)
        why = [
            f"{name(a)}:{line} -> {name(b)}"
            for a in sorted(c)
            for b, line in sorted(edges[a].items())
            if b in inside
        ]
        out.append(([name(k) for k in sorted(c)], why))
    return out


def main():
    crates = [Path(a).resolve() for a in sys.argv[1:]] or sorted(
        p.parent for p in ROOT.glob("*/Cargo.toml") if (p.parent / "src").is_dir()
    )
    bad = 0
    for crate in crates:
        for comp, why in crate_cycles(crate):
            bad += 1
            print(f"import circle in {crate.name}: " + " <-> ".join(comp))
            for w in why:
                print(f"    {w}")
    if bad:
        print(f"{bad} import circle(s) between files", file=sys.stderr)
        return 1
    print(f"no import circle between files in {len(crates)} crates")
    return 0


if __name__ == "__main__":
    sys.exit(main())
