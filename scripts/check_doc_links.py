#!/usr/bin/env python3
"""Checks the relative links of README.md, BENCHMARKS.md and docs/*.md: every linked file
exists and every #anchor names a heading of its target (GitHub's heading slugs)."""
import pathlib
import re
import sys

root = pathlib.Path(__file__).resolve().parent.parent
files = [root / "README.md", root / "BENCHMARKS.md", *sorted((root / "docs").glob("*.md"))]


def slugs(path):
    out, seen, fence = set(), {}, False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fence = not fence
        if fence or not re.match(r"#{1,6} ", line):
            continue
        text = line.lstrip("#").strip().lower()
        slug = re.sub(r"[^\w\- ]", "", text).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


bad = []
for f in files:
    text = re.sub(r"```.*?```", "", f.read_text(), flags=re.S)
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        dest = (f.parent / path).resolve() if path else f
        if not dest.exists():
            bad.append(f"{f.relative_to(root)}: missing file {target}")
        elif anchor and dest.suffix == ".md" and anchor not in slugs(dest):
            bad.append(f"{f.relative_to(root)}: no heading for {target}")
for b in bad:
    print(b, file=sys.stderr)
sys.exit(1 if bad else 0)
