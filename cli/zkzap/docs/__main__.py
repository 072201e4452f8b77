"""``python -m zkzap.docs {all [ROOT] | man OUTDIR | completions OUTDIR | protocol OUTDIR}``."""

from __future__ import annotations

import os
import sys

USAGE = "usage: python -m zkzap.docs {all [ROOT] | man OUTDIR | completions OUTDIR | protocol OUTDIR}"
# all: also share/wireshark/zkzap.lua, docs/protocol.md, docs/reference/commands/*.md and
# cli/zkzap/api/_registers.pyi


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(USAGE, file=sys.stderr if not args else sys.stdout)
        return 2 if not args else 0
    what, rest = args[0], args[1:]
    from . import completions, man, protocol, site, stubs, wireshark

    if what == "all" and len(rest) <= 1:
        root = rest[0] if rest else os.getcwd()
        written = man.generate(os.path.join(root, "man")) + completions.generate(os.path.join(root, "completions"))
        written += wireshark.generate(root) + stubs.generate(root)
        written += protocol.generate(os.path.join(root, "docs")) + site.generate(os.path.join(root, "docs"))
    elif what == "protocol" and len(rest) == 1:
        written = protocol.generate(rest[0])
    elif what == "man" and len(rest) == 1:
        written = man.generate(rest[0])
    elif what == "completions" and len(rest) == 1:
        written = completions.generate(rest[0])
    else:
        print(USAGE, file=sys.stderr)
        return 2
    print(f"{len(written)} files written", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
