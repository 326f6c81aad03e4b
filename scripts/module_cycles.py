#!/usr/bin/env python3
"""Module import cycles in a Rust crate, at file level.

usage: python3 scripts/module_cycles.py [SRC_DIR] [--edges] [--under PREFIX]

Run from the crate root (SRC_DIR defaults to ./src). Every `use` tree and every inline
`crate::`/`super::`/`self::` path (and `trispline::` paths in main.rs) is resolved to the file
that defines the module it names; a path through a `mod.rs`/`lib.rs` re-export (`pub use`)
is followed to the file the item comes from, so a child that imports its parent's re-export
of a sibling counts as importing the sibling. `mod x;` declarations are not edges. Strongly
connected components with more than one file are printed (with the edges inside them when
--edges is given); the exit status is 1 when there is at least one.
--under PREFIX keeps only components with a file whose path starts with PREFIX.
"""
import os
import re
import sys

CRATE_NAME = "trispline"


def strip_comments_and_strings(text):
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            depth, i = 1, i + 2
            while i < n and depth:
                if text.startswith("/*", i):
                    depth, i = depth + 1, i + 2
                elif text.startswith("*/", i):
                    depth, i = depth - 1, i + 2
                else:
                    if text[i] == "\n":
                        out.append("\n")
                    i += 1
        elif c == "r" and re.match(r'r#*"', text[i:i + 10]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'r(#*)"', text[i:])
            end = '"' + m.group(1)
            j = text.find(end, i + len(m.group(0)))
            i = n if j < 0 else j + len(end)
            out.append('""')
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            i = j + 1
            out.append('""')
        elif c == "'":
            # char literal vs lifetime
            m = re.match(r"'(\\.[^']*|[^\\'])'", text[i:])
            if m:
                out.append("' '")
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def module_of(rel):
    """src-relative path -> module path tuple (crate root is ())."""
    parts = rel[:-3].split(os.sep)
    if parts[-1] in ("mod", "lib", "main"):
        parts = parts[:-1]
    return tuple(parts)


def expand_use_tree(tree):
    """'a::{b, c::{d, e}}' -> [['a','b'], ['a','c','d'], ['a','c','e']] (aliases dropped)."""
    tree = re.sub(r"\s+", " ", tree).strip()

    def split_top(s):
        parts, depth, cur = [], 0, ""
        for ch in s:
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
            if ch == "," and depth == 0:
                parts.append(cur)
                cur = ""
            else:
                cur += ch
        if cur.strip():
            parts.append(cur)
        return parts

    def expand(s, prefix):
        s = s.strip()
        if not s:
            return []
        m = re.match(r"^(.*?)::\s*\{(.*)\}$", s, re.S)
        if m and "{" not in m.group(1):
            head = [p.strip() for p in m.group(1).split("::") if p.strip()]
            res = []
            for part in split_top(m.group(2)):
                res += expand(part, prefix + head)
            return res
        if s.startswith("{") and s.endswith("}"):
            res = []
            for part in split_top(s[1:-1]):
                res += expand(part, prefix)
            return res
        s = re.sub(r"\s+as\s+\w+$", "", s)
        segs = [p.strip() for p in s.split("::") if p.strip()]
        if segs and segs[-1] == "self":
            segs = segs[:-1]
        return [prefix + segs]

    return expand(tree, [])


class Crate:
    def __init__(self, src):
        self.src = src
        self.files = {}  # rel -> module tuple
        self.module_file = {}  # module tuple -> rel (lib.rs for ())
        for root, _, names in os.walk(src):
            for name in sorted(names):
                if not name.endswith(".rs"):
                    continue
                rel = os.path.relpath(os.path.join(root, name), src)
                if rel == "main.rs":
                    self.files[rel] = ("<bin>",)
                    continue
                mod = module_of(rel)
                self.files[rel] = mod
                self.module_file[mod] = rel
        self.texts = {}
        for rel in self.files:
            with open(os.path.join(src, rel), encoding="utf-8") as f:
                self.texts[rel] = strip_comments_and_strings(f.read())
        self.reexports = {rel: self.collect_reexports(rel) for rel in self.files}

    def scoped_paths(self, rel):
        """(inline-module path, [segments]) for each use path and inline path in a file."""
        text = self.texts[rel]
        base = self.files[rel]
        results = []
        # inline module nesting: track `mod name {` openings by brace depth
        stack, depth = [], 0
        mod_open = re.compile(r"\bmod\s+(\w+)\s*\{")
        use_re = re.compile(r"\buse\s+([^;]+);")
        path_re = re.compile(r"(?<![\w:])((?:crate|super|self|%s)(?:\s*::\s*\w+)+)" % CRATE_NAME)
        i = 0
        pending = {}
        for m in mod_open.finditer(text):
            pending[m.end() - 1] = m.group(1)
        use_spans = [(m.start(), m.end(), m.group(1)) for m in use_re.finditer(text)]
        use_at = {s: (e, t) for s, e, t in use_spans}
        n = len(text)
        while i < n:
            if i in use_at:
                e, t = use_at[i]
                scope = base + tuple(name for name, _ in stack)
                for segs in expand_use_tree(t):
                    results.append((scope, segs, True))
                i = e
                continue
            c = text[i]
            if c == "{":
                depth += 1
                if i in pending:
                    stack.append((pending[i], depth))
            elif c == "}":
                if stack and stack[-1][1] == depth:
                    stack.pop()
                depth -= 1
            else:
                m = path_re.match(text, i)
                if m and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] in "_:")):
                    scope = base + tuple(name for name, _ in stack)
                    segs = [s.strip() for s in m.group(1).split("::")]
                    results.append((scope, segs, False))
                    i = m.end()
                    continue
            i += 1
        return results

    def absolute(self, scope, segs, is_use):
        """Resolve leading crate/super/self to an absolute module path list."""
        if not segs:
            return None
        head = segs[0]
        if scope and scope[0] == "<bin>":
            if head == CRATE_NAME:
                return list(segs[1:])
            return None
        if head in ("crate", CRATE_NAME):
            return list(segs[1:])
        if head in ("super", "self"):
            cur = list(scope)
            k = 0
            while k < len(segs) and segs[k] in ("super", "self"):
                if segs[k] == "super":
                    if not cur:
                        return None
                    cur.pop()
                k += 1
            return cur + list(segs[k:])
        if is_use:
            # 2018 edition: a use path may start with a name in scope (a child module).
            cand = tuple(scope) + (head,)
            if cand in self.module_file:
                return list(scope) + list(segs)
        return None

    def collect_reexports(self, rel):
        mod = self.files[rel]
        out = {}
        for m in re.finditer(r"\bpub(?:\([^)]*\))?\s+use\s+([^;]+);", self.texts[rel]):
            for segs in expand_use_tree(m.group(1)):
                ab = self.absolute(mod, segs, True)
                if ab and segs[-1] != "*":
                    out[segs[-1]] = ab
        alias = re.finditer(r"\bpub(?:\([^)]*\))?\s+use\s+([\w:]+)\s+as\s+(\w+)\s*;", self.texts[rel])
        for m in alias:
            segs = [s for s in m.group(1).split("::") if s]
            ab = self.absolute(mod, segs, True)
            if ab:
                out[m.group(2)] = ab
        return out

    def resolve_file(self, ab, seen=None):
        """Longest module prefix with a file; follows mod.rs/lib.rs re-exports of the next name."""
        seen = seen or set()
        for k in range(len(ab), -1, -1):
            mod = tuple(ab[:k])
            if mod in self.module_file:
                rel = self.module_file[mod]
                if k < len(ab):
                    name = ab[k]
                    target = self.reexports.get(rel, {}).get(name)
                    key = (rel, name)
                    if target and key not in seen:
                        seen.add(key)
                        return self.resolve_file(target + list(ab[k + 1:]), seen)
                return rel
        return None

    def edges(self):
        g = {rel: set() for rel in self.files}
        for rel in self.files:
            for scope, segs, is_use in self.scoped_paths(rel):
                if segs and segs[-1] == "*":
                    segs = segs[:-1]
                ab = self.absolute(scope, segs, is_use)
                if ab is None:
                    continue
                target = self.resolve_file(ab)
                if target and target != rel:
                    g[rel].add(target)
        return g


def tarjan(g):
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = [0]
    sys.setrecursionlimit(100000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
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
            out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def main(argv):
    src = "src"
    show_edges, under = False, None
    args = list(argv)
    while args:
        a = args.pop(0)
        if a == "--edges":
            show_edges = True
        elif a == "--under":
            under = args.pop(0)
        else:
            src = a
    crate = Crate(src)
    g = crate.edges()
    cycles = [c for c in tarjan(g) if len(c) > 1]
    if under:
        cycles = [c for c in cycles if any(f.startswith(under) for f in c)]
    total = sum(len(v) for v in g.values())
    print(f"{len(g)} files, {total} file-level import edges, {len(cycles)} cycle(s)")
    for c in cycles:
        print("cycle: " + "  ".join(c))
        if show_edges:
            members = set(c)
            for v in c:
                for w in sorted(g[v] & members):
                    print(f"    {v} -> {w}")
    return 1 if cycles else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
