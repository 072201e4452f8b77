"""Every relative link of the README and the manual's sources resolves in the repository as
it is (on GitHub, in a clone), not only in the built site: its target is a file or a folder of
the tree, relative to the page that links to it; a ``#anchor`` of a Markdown target is one of
that page's headings (the site's own check, tests/docs/test_site.py, covers the built pages)."""

from __future__ import annotations

import os
import re

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: ``[text](target)`` and ``![alt](target)``, the text possibly over several lines; a target
#: may carry a title ("...").
LINK = re.compile(r"\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
#: ``[label]: target`` reference definitions.
REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$", re.M)
FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
CODE = re.compile(r"`[^`\n]*`")


def _sources():
    yield os.path.join(REPO, "README.md")
    for d, _, files in os.walk(os.path.join(REPO, "docs")):
        for f in sorted(files):
            if f.endswith(".md"):
                yield os.path.join(d, f)


def _links(text):
    text = CODE.sub("", FENCE.sub("", text))
    return [m.group(1) for m in LINK.finditer(text)] + [m.group(1) for m in REFERENCE.finditer(text)]


def _slug(heading):
    """The anchor MkDocs (and GitHub, for these headings) gives a heading: ``{ #id }`` if given."""
    m = re.search(r"\{\s*#([\w-]+)\s*\}\s*$", heading)
    if m:
        return m.group(1)
    text = re.sub(r"[^\w\s-]", "", heading).strip().lower()      # Python-Markdown's toc slugify
    return re.sub(r"[-\s]+", "-", text)


def _anchors(path):
    with open(path, encoding="utf-8") as f:
        text = FENCE.sub("", f.read())
    ids = {_slug(h) for h in re.findall(r"^#{1,6}\s+(.+?)\s*#*\s*$", text, re.M)}
    ids |= set(re.findall(r"""(?:id|name)=["']([^"']+)["']""", text))
    ids |= set(re.findall(r"\{\s*[^}]*#([\w-]+)[^}]*\}", text))
    return ids


@pytest.mark.parametrize("page", list(_sources()), ids=lambda p: os.path.relpath(p, REPO))
def test_every_relative_link_resolves_in_the_tree(page):
    with open(page, encoding="utf-8") as f:
        links = _links(f.read())
    dead = []
    for target in links:
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#") or target.startswith("/"):
            continue            # a URL, mail, an anchor of this page (the site's check), a root path
        path, _, anchor = target.partition("#")
        where = os.path.normpath(os.path.join(os.path.dirname(page), path.split("?")[0]))
        if not os.path.exists(where):
            dead.append(target)
        elif anchor and where.endswith(".md") and anchor not in _anchors(where):
            dead.append(target)
    assert not dead, f"{os.path.relpath(page, REPO)}: dead links: {', '.join(dead)}"


def test_the_links_to_the_command_reference_are_checked():
    """The README and the manual link to the command reference; those links are among the ones
    checked (the pattern finds links whose text runs over several lines)."""
    reference = os.path.join(REPO, "docs", "reference", "commands")
    found = 0
    for page in _sources():
        if os.path.dirname(page) == reference:
            continue
        with open(page, encoding="utf-8") as f:
            found += sum(os.path.dirname(os.path.normpath(os.path.join(os.path.dirname(page), t.partition("#")[0])))
                         == reference for t in _links(f.read()))
    assert found >= 17
