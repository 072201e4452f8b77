"""The floor: the least work that turns a ZK status capture into JSON Lines.

Assumes what a real decoder cannot (every frame is 7 bytes and aligned: no sync search, no
control frames, no garbage), checks each CRC with the same table, and writes ``json.dumps`` of
a five-field dict (id, rpm and the three raw payload bytes) per frame. No names, no units, no
scaling. ``zk_decode.py`` measures ``zk decode --binary`` against this.

    python benchmarks/floor_zk_decode.py CAPTURE [--format jsonl|csv] > out
"""

import argparse
import json
import sys

T = bytearray(256)
for _i in range(256):
    _c = _i
    for _ in range(8):
        _c = (_c >> 1) ^ 0x8C if _c & 1 else _c >> 1
    T[_i] = _c
T = bytes(T)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("capture")
    ap.add_argument("--format", choices=["jsonl", "csv"], default="jsonl")
    args = ap.parse_args()
    dumps = json.dumps
    out = sys.stdout
    write = out.write
    bad = 0
    csv = args.format == "csv"
    if csv:
        write("id,rpm,b3,b4,b5\n")
    with open(args.capture, "rb") as f:
        while True:
            block = f.read(7 * 9362)
            if not block:
                break
            lines = []
            append = lines.append
            for i in range(0, len(block) - 6, 7):
                b = block[i:i + 7]
                if T[T[T[T[T[T[b[0]] ^ b[1]] ^ b[2]] ^ b[3]] ^ b[4]] ^ b[5]] != b[6]:
                    bad += 1
                    continue
                if csv:
                    append(f"{b[0] & 15},{(b[2] << 8 | b[1]) * 10},{b[3]},{b[4]},{b[5]}")
                else:
                    append(dumps({"id": b[0] & 15, "rpm": (b[2] << 8 | b[1]) * 10, "b3": b[3], "b4": b[4],
                                  "b5": b[5]}))
            lines.append("")
            write("\n".join(lines))
    out.flush()
    if bad:
        print(f"{bad} bad frames", file=sys.stderr)


if __name__ == "__main__":
    main()
