"""The documentation site (MkDocs with Material and mkdocstrings, the ``docs`` extra): the pages
generated while it builds, and the docstring dialect of the API reference.

    pip install '.[docs]' && mkdocs build --strict        # the site, into site/
    mkdocs serve                                           # the same, live

The command reference (one page per command group, ``docs/reference/commands/*.md``) is written
from the click application as the man pages are, by :func:`generate` (``python -m zkzap.docs
all``), and committed like them: the README's and the manual's links to it resolve on GitHub and
in a clone as well as in the built site (the tests fail when a committed page differs). The
protocol reference ``docs/protocol.md`` is written from the codec's tables and committed too.
``mkdocs.yml`` names this file as a hook for the docstrings' dialect below.
:class:`SphinxRoles` is a griffe extension that
reads the docstrings' reStructuredText roles (``:class:`Bus```, ``:meth:`~Bus.move```) as
cross-references, their ``>>>`` sessions and ``.. code-block::`` directives as code blocks.

The hook is loaded by path, so this module imports zkzap absolutely.
"""

from __future__ import annotations

import re

#: The command reference: one page per top-level group of ``zkzap``, under this folder.
COMMANDS_DIR = "reference/commands"


# --- the command reference -----------------------------------------------------------------------

def _md(text: str) -> str:
    """Help text as Markdown text: nothing it contains is read as Markdown or HTML."""
    return re.sub(r"([\\`*_\[\]<>|#])", r"\\\1", text)


def _anchor(path) -> str:
    return "-".join(path)


def _exit_rows(cmd) -> list:
    from zkzap.docs.man import exit_statuses

    return [f"| {code} | {_md(text)} |" for code, text in exit_statuses(cmd)]


def _command_section(page, level: int) -> list:
    """One command's section: usage, description, examples, arguments, options, exit status."""
    import click

    from zkzap.docs import man

    cmd, ctx = page.cmd, page.ctx
    title = " ".join(page.path)
    out = [f"{'#' * level} {title} {{ #{_anchor(page.path)} }}", ""]
    usage = " ".join(cmd.collect_usage_pieces(ctx))
    forms = [" ".join(page.path)]
    if len(page.path) > 1 and page.path[1] in man.ENTRY_POINTS:
        forms.append(" ".join(page.path[1:]))
    out += ["```text", *(f"{form} {usage}" for form in forms), "```", ""]
    desc, examples = man.split_examples(cmd.help)
    for verbatim, lines in desc:
        if verbatim:
            out += ["```text", *lines, "```", ""]
        else:
            out += [_md(" ".join(lines)), ""]
    if not desc:
        out += [_md(man.short_help(cmd) + "."), ""]
    if examples:
        out += ["Examples:", "", "```sh", *examples, "```", ""]
    if page.children:
        out += ["| command | what it does |", "| --- | --- |"]
        for child in page.children:
            where = f"{child.path[-1]}.md" if page.parent is None and child.is_group else ""
            out.append(f"| [{' '.join(child.path[1:])}]({where}#{_anchor(child.path)}) | "
                       f"{_md(man.short_help(child.cmd))} |")
        out.append("")
    args = [p for p in cmd.get_params(ctx) if isinstance(p, click.Argument)]
    if args:
        out += ["| argument | |", "| --- | --- |"]
        for p in args:
            metavar = p.make_metavar(ctx) if man._takes_ctx(p.make_metavar) else p.make_metavar()
            text = []
            if isinstance(p.type, click.Choice):
                text.append("One of: " + ", ".join(f"`{c}`" for c in p.type.choices) + ".")
            text.append("Required." if p.required else "Optional.")
            if p.nargs == -1:
                text.append("May be repeated.")
            out.append(f"| `{metavar}` | {' '.join(text)} |")
        out.append("")
    records = [p.get_help_record(ctx) for p in cmd.get_params(ctx) if isinstance(p, click.Option) and not p.hidden]
    records = [r for r in records if r is not None]
    if records:
        out += ["| option | |", "| --- | --- |"]
        for names, text in records:
            out.append(f"| `{names}` | {_md(' '.join(text.split())) or '(no description)'} |")
        out.append("")
    if not page.is_group:
        out += ["Exit status:", "", "| status | meaning |", "| --- | --- |", *_exit_rows(cmd), ""]
        if getattr(cmd, "exit_tail", ""):
            out += [_md(cmd.exit_tail.strip()), ""]
    return out


def command_pages() -> dict:
    """``{path under the docs folder: Markdown}``: the root's page (its own commands) and one page
    per top-level group, each command a section with an anchor ``zkzap-zk-send-control``."""
    from zkzap.docs import man

    root = man.tree()
    pages = {}
    own = [c for c in root.children if not c.is_group]
    text = ["# zkzap", "",
            "The root command and its own commands. Each group has its page: "
            + ", ".join(f"[zkzap {c.path[-1]}]({c.path[-1]}.md)" for c in root.children if c.is_group) + ".",
            "Written from the command-line application itself, as the man pages are.", ""]
    text += _command_section(root, 2)
    for child in own:
        text += _command_section(child, 2)
    pages[f"{COMMANDS_DIR}/zkzap.md"] = "\n".join(text)
    for group in (c for c in root.children if c.is_group):
        text = [f"# zkzap {group.path[-1]}", "",
                "Written from the command-line application itself, as the man pages are.", ""]
        for page in group.walk():
            text += _command_section(page, 2 if page is group else 3)
        pages[f"{COMMANDS_DIR}/{group.path[-1]}.md"] = "\n".join(text)
    return pages


def generate(docs_dir) -> list:
    """Write the command reference under ``DOCS_DIR/reference/commands`` (a page no group has any
    more is removed); returns the paths written."""
    import os

    pages = command_pages()
    folder = os.path.join(docs_dir, COMMANDS_DIR)
    os.makedirs(folder, exist_ok=True)
    keep = {os.path.basename(src) for src in pages}
    for old in os.listdir(folder):
        if old.endswith(".md") and old not in keep:
            os.remove(os.path.join(folder, old))
    written = []
    for src, text in pages.items():
        path = os.path.join(docs_dir, src)
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(text if text.endswith("\n") else text + "\n")
        written.append(path)
    return written


# --- the docstrings' dialect -----------------------------------------------------------------------

_ROLE = re.compile(r":(?:py:)?(class|meth|func|mod|attr|data|exc|obj|const):`(~?)([^`<]+?)(?:\s*<([^>]+)>)?`")


def _fences(text: str) -> str:
    """``>>>`` sessions and ``.. code-block:: LANG`` blocks as fenced code blocks."""
    lines = text.split("\n")
    out = []
    i = 0
    while i < len(lines):
        ln = lines[i]
        stripped = ln.strip()
        m = re.match(r"(\s*)\.\. code-block::\s*(\w*)\s*$", ln)
        if m:
            i += 1
            while i < len(lines) and not lines[i].strip():
                i += 1
            block = []
            while i < len(lines) and (not lines[i].strip() or len(lines[i]) - len(lines[i].lstrip()) > len(m.group(1))):
                block.append(lines[i])
                i += 1
            while block and not block[-1].strip():
                block.pop()
            indent = min((len(b) - len(b.lstrip()) for b in block if b.strip()), default=0)
            out += [f"{m.group(1)}```{m.group(2) or 'text'}", *(b[indent:] for b in block), f"{m.group(1)}```", ""]
            continue
        if stripped.startswith(">>>"):
            block = []
            while i < len(lines) and lines[i].strip():
                block.append(lines[i].strip())
                i += 1
            out += ["```pycon", *block, "```"]
            continue
        out.append(ln)
        i += 1
    return "\n".join(out)


def rst_to_markdown(text: str, resolve) -> str:
    """A docstring's reStructuredText roles as cross-references (``resolve(name)`` gives the
    full path of a name, or None: then the name is only code), its ``>>>`` sessions and
    code-block directives as fenced code."""
    def role(m):
        tilde, target, explicit = m.group(2), m.group(3).strip(), m.group(4)
        if explicit:
            title, target = target, explicit.strip()
        else:
            title = target.rsplit(".", 1)[-1] if tilde else target
        if m.group(1) in ("meth", "func") and not title.endswith(")"):
            title += "()"
        full = resolve(target.lstrip("~."))
        code = f"<code>{title}</code>"
        return f'<autoref identifier="{full}" optional>{code}</autoref>' if full else code

    return _ROLE.sub(role, _fences(text))


try:
    import griffe as _griffe
except ImportError:                      # not building the site: the class is not needed
    _griffe = None

if _griffe is not None:
    class SphinxRoles(_griffe.Extension):
        """Griffe extension: every docstring of the loaded package through :func:`rst_to_markdown`."""

        def on_package(self, *, pkg, **kwargs):
            for obj in _walk(pkg):
                if obj.docstring is not None:
                    obj.docstring.value = rst_to_markdown(obj.docstring.value, lambda name, o=obj: _resolve(o, name))

    def _walk(obj, seen=None):
        seen = set() if seen is None else seen
        if id(obj) in seen or obj.is_alias:
            return
        seen.add(id(obj))
        yield obj
        for member in list(obj.members.values()):
            if not member.is_alias:
                yield from _walk(member, seen)

    def _resolve(obj, name):
        """The full path of ``name`` seen from ``obj`` (its scope, then the package), or None."""
        head, _, rest = name.partition(".")
        scope = obj
        while scope is not None:
            try:
                full = scope.resolve(head)
            except Exception:  # noqa: BLE001 - griffe's NameResolutionError, or an alias it cannot follow
                full = None
            if full:
                return f"{full}.{rest}" if rest else full
            scope = scope.parent
        return name if name.startswith("zkzap.") else None
