"""Generators for the committed ``man/`` pages, ``completions/`` scripts and the protocol
reference ``docs/protocol.md``, and for the API reference (pdoc, not committed).

    python -m zkzap.docs all [ROOT]            # man/, completions/ and docs/protocol.md under ROOT
    python -m zkzap.docs man OUTDIR
    python -m zkzap.docs completions OUTDIR
    python -m zkzap.docs protocol OUTDIR
    python -m zkzap.docs api [OUTDIR]          # HTML from the docstrings (pip install 'zkzap[docs]')

The man pages and completions walk the click application, so they follow every command,
option and help text; the protocol reference is written from the codec's tables.
"""
