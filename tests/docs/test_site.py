"""The manual builds with MkDocs in strict mode (every warning an error: a broken link or anchor
in a page, an unknown cross-reference, a page left out of the navigation), and every link and
anchor of the built site resolves, without the network."""

from __future__ import annotations

import os
import posixpath
import subprocess
import sys
from html.parser import HTMLParser
from urllib.parse import unquote, urlsplit

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    pytest.importorskip("mkdocs", reason="the docs extra (pip install '.[docs]') is not installed")
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    p = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                       cwd=REPO, capture_output=True, text=True, env=env, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "WARNING" not in p.stdout + p.stderr, p.stdout + p.stderr
    return out


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.ids, self.links = set(), []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("id", "name"):
            if a.get(key):
                self.ids.add(a[key])
        for key in ("href", "src"):
            if a.get(key) and tag in ("a", "link", "script", "img"):
                self.links.append(a[key])


def _pages(root):
    pages = {}
    for dirpath, _, files in os.walk(root):
        for name in files:
            if name.endswith(".html"):
                path = os.path.join(dirpath, name)
                page = _Page()
                page.feed(open(path, encoding="utf-8").read())
                pages[os.path.relpath(path, root).replace(os.sep, "/")] = page
    return pages


def test_every_internal_link_and_anchor_resolves(site):
    pages = _pages(site)
    assert len(pages) > 40
    broken = []
    for name, page in pages.items():
        for link in page.links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc or link.startswith(("mailto:", "data:", "javascript:")):
                continue
            if not parts.path:
                target = name
            elif parts.path.startswith("/"):                 # 404.html: from the site's root
                target = unquote(parts.path).lstrip("/")
            else:
                target = posixpath.normpath(posixpath.join(posixpath.dirname(name), unquote(parts.path)))
            if target.endswith("/") or os.path.isdir(os.path.join(site, target)):
                target = posixpath.join(target, "index.html")
            if not os.path.exists(os.path.join(site, target)):
                broken.append(f"{name}: {link} (no {target})")
            elif parts.fragment and target in pages and unquote(parts.fragment) not in pages[target].ids:
                broken.append(f"{name}: {link} (no anchor #{parts.fragment} in {target})")
    assert broken == []


def test_the_command_reference_has_every_command(site):
    from cmdtree import commands

    pages = _pages(site)
    ids = {i for name, page in pages.items() if name.startswith("reference/commands/") for i in page.ids}
    missing = ["zkzap " + " ".join(path) for path, _ in commands(hidden=False)
               if "-".join(("zkzap", *path)) not in ids]
    assert missing == []
    zk_send = open(os.path.join(site, "reference", "commands", "zk.html"), encoding="utf-8").read()
    assert "--throttle" in zk_send and "ZKZAP_ZK_PORT" in zk_send and "Exit status" in zk_send


def test_the_api_reference_is_written_from_the_code(site):
    text = open(os.path.join(site, "reference", "api", "zap.html"), encoding="utf-8").read()
    for name in ("present_voltage", "set_baud", "zkzap.api.zap.Bus.move", "Reading"):
        assert name in text
    assert ":class:" not in text and ":meth:" not in text          # the roles became references
    errors = open(os.path.join(site, "reference", "api", "errors.html"), encoding="utf-8").read()
    assert "InvalidValue" in errors and "did_you_mean" in errors
