"""Generators for the committed ``man/`` pages and ``completions/`` scripts.

    python -m zkzap.docs all [ROOT]            # man pages into ROOT/man, scripts into ROOT/completions
    python -m zkzap.docs man OUTDIR
    python -m zkzap.docs completions OUTDIR

Both walk the click application, so they follow every command, option and help text.
"""
