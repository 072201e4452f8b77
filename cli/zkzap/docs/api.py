"""The API reference: HTML generated from the docstrings with pdoc (the optional ``docs``
extra), into ``docs/api/``.

    python -m zkzap.docs api [OUTDIR]        # default docs/api

Documented: the public library (``zkzap``, ``zkzap.api``, ``zkzap.codec``, ``zkzap.sim``,
``zkzap.link``, ``zkzap.errors`` and the pytest plugin); the command-line modules, the writers
and these generators are the application, not the library.
"""

from __future__ import annotations

import os

#: The documented modules: the library, not the application's command and writer modules.
MODULES = ("zkzap", "zkzap.api", "zkzap.errors", "zkzap.codec", "zkzap.codec.zk", "zkzap.codec.zap",
           "zkzap.codec.framing", "zkzap.codec.crc", "zkzap.codec.fields", "zkzap.codec.hexfmt", "zkzap.sim",
           "zkzap.link", "zkzap.pytest_plugin")


def generate(outdir) -> list:
    """Render the reference into ``outdir``; returns the files written. Raises ImportError
    naming the extra when pdoc is not installed."""
    try:
        import pdoc
        import pdoc.render
    except ImportError:
        raise ImportError("the API reference needs pdoc: pip install 'zkzap[docs]'") from None
    import importlib
    from pathlib import Path

    for name in ("zkzap", "zkzap.codec"):            # resolve the lazy re-exports for pdoc
        module = importlib.import_module(name)
        for attr in getattr(module, "__all__", ()):
            getattr(module, attr)

    pdoc.render.configure(docformat="restructuredtext", footer_text="zkzap", search=True,
                          show_source=False)
    out = Path(outdir)
    pdoc.pdoc(*MODULES, output_directory=out)
    return [str(p) for p in sorted(out.rglob("*")) if p.is_file()]


def default_dir(root=None) -> str:
    return os.path.join(root or os.getcwd(), "docs", "api")
