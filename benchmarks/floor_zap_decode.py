"""The floor: the least work that turns a mightyZAP capture into JSON Lines or CSV.

Finds each packet by its SIZE byte (assumes the capture is whole packets, no garbage: no sync
search), checks its checksum, and writes ``json.dumps`` of a five-field dict (id, the
instruction/error byte, the parameter count and the first two parameter bytes) per packet, or
those five numbers as a CSV row. No names, no pairing, no units. ``zap_decode.py`` measures
``zap decode --binary`` against this.

    python benchmarks/floor_zap_decode.py CAPTURE [--format jsonl|csv] > out
"""

import argparse
import json
import sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("capture")
    ap.add_argument("--format", choices=["jsonl", "csv"], default="jsonl")
    args = ap.parse_args()
    dumps = json.dumps
    write = sys.stdout.write
    csv = args.format == "csv"
    bad = 0
    if csv:
        write("id,code,n,p1,p2\n")
    with open(args.capture, "rb") as f:
        data = f.read()
    i, end = 0, len(data)
    lines = []
    append = lines.append
    while i + 7 <= end:
        size = data[i + 4]
        n = size + 5
        p = data[i:i + n]
        i += n
        if (0xFF - (sum(p[3:-1]) & 0xFF)) != p[-1]:
            bad += 1
            continue
        k = size - 2
        p1 = p[6] if k > 0 else None
        p2 = p[7] if k > 1 else None
        if csv:
            append(f"{p[3]},{p[5]},{k},{'' if p1 is None else p1},{'' if p2 is None else p2}")
        else:
            append(dumps({"id": p[3], "code": p[5], "n": k, "p1": p1, "p2": p2}))
        if len(lines) >= 8192:
            lines.append("")
            write("\n".join(lines))
            lines.clear()
    if lines:
        lines.append("")
        write("\n".join(lines))
    if bad:
        print(f"{bad} bad packets", file=sys.stderr)


if __name__ == "__main__":
    main()
