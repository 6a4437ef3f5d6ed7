#!/usr/bin/env python3
"""Every link and cited repository path in the repository's Markdown files resolves.

Checked, outside fenced code blocks (those hold commands, whose paths are often outputs):
- relative links and images, [text](path) and ![alt](path), against the page's own folder;
- paths in backticks or plain text whose first part is a top-level folder of the repository
  (`docs/bench/`, renderer/cpu/cpu_march.cpp), against the repository's root;
- `git show COMMIT:path` in backticks, against that commit, when the checkout has history.

Prints each path that does not resolve with the page and line citing it, and exits 1 if any.
Usage: check_links.py [REPOSITORY_ROOT]  (default: two folders above this file)
"""

import glob
import os
import re
import subprocess
import sys

# A cited path with these is a placeholder, not a file; one with * or ? is a pattern that must
# match at least one file.
PLACEHOLDER_CHARS = set("{}<>$|…[]")
GLOB_CHARS = set("*?")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
CODE_SPAN = re.compile(r"`([^`\n]+)`")
GIT_SHOW = re.compile(r"^git show ([0-9a-f]{7,40}):(\S+)$")
SKIPPED_DIRS = {".git", "node_modules", "build", "out", "shared", ".device-bundle"}


def markdown_files(root):
    try:
        listed = subprocess.run(["git", "-C", root, "ls-files", "-co", "--exclude-standard", "*.md"],
                                check=True, capture_output=True, text=True).stdout.split("\n")
        return sorted(os.path.join(root, f) for f in listed if f and os.path.isfile(os.path.join(root, f)))
    except (OSError, subprocess.CalledProcessError):
        found = []
        for folder, dirs, files in os.walk(root):
            dirs[:] = [d for d in dirs if d not in SKIPPED_DIRS and not d.startswith("build")]
            found += [os.path.join(folder, f) for f in files if f.endswith(".md")]
        return sorted(found)


def lines_outside_code_blocks(text):
    fence = None
    for number, line in enumerate(text.split("\n"), 1):
        stripped = line.lstrip()
        marker = stripped[:3]
        if marker in ("```", "~~~"):
            if fence is None:
                fence = marker
            elif marker == fence:
                fence = None
            continue
        if fence is None and not line.startswith("    "):
            yield number, line


def have_commit(root, commit, cache={}):
    if commit not in cache:
        cache[commit] = subprocess.run(["git", "-C", root, "cat-file", "-e", commit + "^{commit}"],
                                       capture_output=True).returncode == 0
    return cache[commit]


def in_commit(root, commit, path):
    return subprocess.run(["git", "-C", root, "cat-file", "-e", f"{commit}:{path.rstrip('/')}"],
                          capture_output=True).returncode == 0


def cited_paths(line, top_level):
    """Candidate repository paths in a line: backticked or plain, starting with a top-level folder."""
    starts = "|".join(re.escape(d) for d in sorted(top_level, key=len, reverse=True))
    plain = re.compile(r"(?<![\w./:-])((?:" + starts + r")/[\w./+-]*)")
    for match in plain.finditer(CODE_SPAN.sub(lambda m: " " * len(m.group(0)), line)):
        yield match.group(1)
    for span in CODE_SPAN.findall(line):
        word = span.split()[0] if span.split() else ""
        if word.split("/")[0] in top_level and "/" in word:
            yield word


def check(root):
    root = os.path.abspath(root)
    top_level = {d for d in os.listdir(root)
                 if os.path.isdir(os.path.join(root, d)) and d not in SKIPPED_DIRS and not d.startswith((".", "build"))}
    problems = []
    pages = markdown_files(root)
    for page in pages:
        folder = os.path.dirname(page)
        shown = os.path.relpath(page, root)
        with open(page, encoding="utf-8") as f:
            text = f.read()
        for number, line in lines_outside_code_blocks(text):
            for target in LINK.findall(line):
                if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
                    continue
                path = target.split("#")[0]
                if path and not os.path.exists(os.path.normpath(os.path.join(folder, path))):
                    problems.append(f"{shown}:{number}: link to {target} does not resolve")
            for span in CODE_SPAN.findall(line):
                show = GIT_SHOW.match(span)
                if show and not PLACEHOLDER_CHARS & set(span) and have_commit(root, show.group(1)) and not in_commit(root, *show.groups()):
                    problems.append(f"{shown}:{number}: `{span}` names nothing in that commit")
            for path in cited_paths(line, top_level):
                path = path.rstrip(".,;:")
                if (PLACEHOLDER_CHARS & set(path) or SKIPPED_DIRS & set(path.split("/"))
                        or f"git show" in line and f":{path}" in line):
                    continue
                if GLOB_CHARS & set(path):
                    if not glob.glob(os.path.join(root, path)):
                        problems.append(f"{shown}:{number}: {path} matches nothing")
                elif not os.path.exists(os.path.join(root, path)):
                    problems.append(f"{shown}:{number}: {path} does not exist")
    return pages, problems


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "..")
    pages, problems = check(root)
    for problem in problems:
        print(problem)
    print(f"{len(pages)} Markdown files checked, {len(problems)} paths that do not resolve")
    return 1 if problems or not pages else 0


if __name__ == "__main__":
    sys.exit(main())
