#!/usr/bin/env python3
"""Checks that every relative link in the README, CHANGELOG and docs/ resolves.

    python3 tools/check_links.py [FILE.md ...]

Without arguments it reads README.md, CHANGELOG.md and docs/**/*.md of the checkout this script
lies in. A link is `[text](target)`, `![alt](target)` or a reference definition
`[name]: target`, outside code blocks and code spans. Targets with a scheme (http, https,
mailto, ...) are left alone. A relative target must name an existing file or folder (relative
to the linking file; a leading `/` means the checkout's root). An anchor (`path#anchor`, or
`#anchor` in the same file) into a Markdown file must name one of its headings, slugged as
GitHub does: the heading's text lower-cased, punctuation other than `-` and `_` dropped, each
space turned into `-`, and `-1`, `-2`, ... appended to repeats. Anchors into other files (a
source file's `#L10`) are not checked.

Prints each broken link as `FILE:LINE: target (why)` and exits 1 if there is any; standard
library only.
"""

import re
import sys
import urllib.parse
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
CODE_SPAN = re.compile(r"(`+)(.+?)\1")
# [text](target "title") and ![alt](target); the text may hold one level of brackets.
INLINE_LINK = re.compile(
    r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*(<[^>]*>|[^()\s]+(?:\([^()\s]*\)[^()\s]*)*)"
    r"(?:\s+(?:\"[^\"]*\"|'[^']*'|\([^()]*\)))?\s*\)"
)
REFERENCE_DEFINITION = re.compile(r"^ {0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
ATX_HEADING = re.compile(r"^ {0,3}(#{1,6})(?:[ \t]+(.*?))?(?:[ \t]+#+)?[ \t]*$")
SETEXT_UNDERLINE = re.compile(r"^ {0,3}(=+|-+)[ \t]*$")
HTML_ANCHOR = re.compile(r"<[^>]*\s(?:id|name)\s*=\s*[\"']([^\"']+)[\"']", re.IGNORECASE)


def lines_outside_code(text):
    """(line number, line) for every line outside fenced code blocks."""
    fence = None
    for number, line in enumerate(text.splitlines(), start=1):
        match = FENCE.match(line)
        if fence is None:
            if match:
                fence = match.group(1)
                continue
            yield number, line
        elif (
            match
            and match.group(1)[0] == fence[0]
            and len(match.group(1)) >= len(fence)
            and line.strip() == match.group(1)
        ):
            fence = None


def heading_text(raw):
    """A heading's text as GitHub renders it (code spans, links and images to their text)."""
    text = CODE_SPAN.sub(lambda m: m.group(2).strip(), raw)
    text = re.sub(r"!?\[((?:[^\[\]]|\[[^\[\]]*\])*)\]\([^)]*\)", r"\1", text)
    text = re.sub(r"<[^>]+>", "", text)
    return text.strip()


def slug(text):
    text = heading_text(text).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors_of(path, cache={}):
    """The anchors a Markdown file's headings (and HTML ids) give it."""
    if path not in cache:
        text = path.read_text(encoding="utf-8")
        anchors = set()
        seen = {}
        previous = ""
        for _, line in lines_outside_code(text):
            heading = None
            atx = ATX_HEADING.match(line)
            if atx:
                heading = atx.group(2) or ""
            elif (
                SETEXT_UNDERLINE.match(line)
                and previous.strip()
                and not previous.lstrip().startswith(("|", "-", "*", "+", ">"))
            ):
                heading = previous.strip()
            if heading is not None:
                base = slug(heading)
                count = seen.get(base, 0)
                seen[base] = count + 1
                anchors.add(base if count == 0 else f"{base}-{count}")
            anchors.update(HTML_ANCHOR.findall(line))
            previous = line if not atx else ""
        cache[path] = anchors
    return cache[path]


def links_in(path):
    """(line number, target) of every link in a Markdown file, outside code."""
    text = path.read_text(encoding="utf-8")
    for number, line in lines_outside_code(text):
        # Code spans hold example syntax, not links.
        stripped = CODE_SPAN.sub(lambda m: " " * len(m.group(0)), line)
        definition = REFERENCE_DEFINITION.match(stripped)
        if definition:
            yield number, definition.group(1)
        for match in INLINE_LINK.finditer(stripped):
            yield number, match.group(1)


def is_external(target):
    """A link with a scheme (http, https, mailto, ...) or a network path: not checked."""
    target = target.strip("<>")
    return bool(SCHEME.match(target)) or target.startswith("//")


def problem(source, target):
    """Why the relative `target`, linked from `source`, does not resolve (None when it does)."""
    target = target.strip("<>")
    path_part, _, anchor = target.partition("#")
    path_part = urllib.parse.unquote(path_part.split("?", 1)[0])
    if not path_part:
        resolved = source
    elif path_part.startswith("/"):
        resolved = ROOT / path_part.lstrip("/")
    else:
        resolved = source.parent / path_part
    if not resolved.exists():
        return "no such file or folder"
    if anchor and resolved.is_file() and resolved.suffix.lower() in (".md", ".markdown"):
        if urllib.parse.unquote(anchor).lower() not in anchors_of(resolved.resolve()):
            return f"no heading for #{anchor} in {shown(resolved.resolve())}"
    return None


def shown(path):
    """`path` relative to the checkout where it lies in it."""
    try:
        return path.relative_to(ROOT)
    except ValueError:
        return path


def default_files():
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md"]
    files += sorted((ROOT / "docs").rglob("*.md"))
    return files


def main(argv):
    files = [Path(a).resolve() for a in argv] if argv else default_files()
    broken = []
    checked = 0
    for path in files:
        if not path.is_file():
            broken.append(f"{path}: the file to check is missing")
            continue
        for number, target in links_in(path):
            if is_external(target):
                continue
            why = problem(path, target)
            if why is None:
                checked += 1
            else:
                broken.append(f"{shown(path)}:{number}: {target} ({why})")
    if broken:
        print("\n".join(broken))
        print(f"check_links: {len(broken)} broken link(s)", file=sys.stderr)
        return 1
    print(f"check_links: {checked} relative links in {len(files)} files resolve")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
