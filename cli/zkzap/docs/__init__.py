"""Generators for the committed ``man/`` pages, ``completions/`` scripts, the protocol
reference ``docs/protocol.md``, the Wireshark dissector and the Actuator's register stub, and
the pages the manual generates while it builds (:mod:`zkzap.docs.site`).

    python -m zkzap.docs all [ROOT]            # man/, completions/, docs/protocol.md, ... under ROOT
    python -m zkzap.docs man OUTDIR
    python -m zkzap.docs completions OUTDIR
    python -m zkzap.docs protocol OUTDIR
    mkdocs build --strict                      # the manual (pip install 'zkzap[docs]')

The man pages, completions and the command reference walk the click application, so they
follow every command, option and help text; the protocol reference and the stub are written
from the codec's tables.
"""
