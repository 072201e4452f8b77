"""The protocol reference ``docs/protocol.md``, written from the codec's tables, so that it
cannot drift from what zkzap does (the decisions where the specifications are open are
``docs/decisions.md``, written by hand).

    python -m zkzap.docs protocol OUTDIR        # (also part of 'all')
"""

from __future__ import annotations

import os

from ..codec import zap, zk
from ..codec.fields import bits_text, scale_text

NOTATION = """\
Bit notation: bytes are numbered from 0 (the head byte); `b2` is byte 2, `b3[4:0]` its bits 4
down to 0, `b4[1:0] b3[7:5]` a value whose high bits are byte 4's bits 1..0 and whose low bits
are byte 3's bits 7..5 (most significant part first). Multi-byte values in the mightyZAP
protocol are little-endian."""


def _cell(value) -> str:
    text = "" if value is None else str(value)
    return text.replace("|", "\\|").replace("\n", " ")


def _table(head, rows) -> list:
    out = ["| " + " | ".join(head) + " |", "| " + " | ".join("---" for _ in head) + " |"]
    out += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return out + [""]


def _scale(field) -> str:
    s = scale_text(field)
    return "" if s is None or s == 1 else s if isinstance(s, str) else f"{s:g}"


def _range(field) -> str:
    try:
        return field.describe_range()
    except Exception:  # noqa: BLE001 - a context-dependent scale (rpm factor): the raw range
        return f"{field.lo}..{field.hi} (raw)"


def _zk() -> list:
    out = ["## ZK turbine ECU protocol (V1.2, with the V1.4 additions)", "",
           "Control frames (host -> ECU) are 4 bytes: `FF` head, `b1` (high nibble: the command ID), "
           "`b2`, and a CRC-8/MAXIM-DOW over bytes 1..2. Status frames (ECU -> host) are 7 bytes: "
           "`F0 | ID`, `b1..b5`, and a CRC-8/MAXIM-DOW over bytes 0..5. Every status frame carries "
           "`rpm` in `b2 b1` (x 10 rpm).", "", NOTATION, "", "### Control commands", ""]
    rows = []
    for c in zk.CONTROL:
        rows.append((c.id, c.name, c.since, c.hazard or "", "yes" if c.needs_unlock else "", c.help))
    out += _table(("ID", "name", "since", "can", "needs unlock", "meaning"), rows)
    out += ["### Control fields", ""]
    rows = []
    for c in zk.CONTROL:
        for f in c.fields:
            rows.append((c.id, f.key, bits_text(f), _scale(f), f.unit, _range(f), f.since, f.help))
    out += _table(("ID", "key", "bits", "scale", "unit", "range", "since", "meaning"), rows)
    out += ["### Status frames", ""]
    rows = []
    for s in zk.STATUS:
        for f in s.fields:
            rows.append((s.id, s.name, f.key, bits_text(f), _scale(f), f.unit, f.since, f.help))
    out += _table(("ID", "frame", "key", "bits", "scale", "unit", "since", "meaning"), rows)
    out += ["### Engine states (status ID 1)", ""]
    out += _table(("code", "name", "meaning"), [(k, v, zk.ENGINE_STATE_TEXT.get(k, "")) for k, v in
                                              zk.ENGINE_STATES.items()])
    out += ["### Error codes (status ID 1)", ""]
    out += _table(("code", "name", "meaning"), [(k, v, zk.ERROR_TEXT.get(k, "")) for k, v in zk.ERRORS.items()])
    out += ["### Actions (control ID 2)", ""]
    out += _table(("param", "name", "since", "runs hardware", "meaning"),
                  [(k, v, zk.ACTION_SINCE.get(k, 1), "yes" if k in zk.HAZARDOUS_ACTIONS else "",
                    zk.ACTION_TEXT.get(k, "")) for k, v in zk.ACTIONS.items()])
    out += ["### Safety", "",
            "A frame is hazardous (it needs consent on a real port) when it is control ID 1 or 6 with "
            "state run, or an action that runs hardware (above). A session controls the engine once "
            "it sent control ID 1 with a state other than pwm, ID 6 with a state or an RPM factor, "
            "ID 7, or a hardware action; such a session sends the abort command when it ends "
            f"abnormally: one of {', '.join(zk.ABORTS)} (default {zk.DEFAULT_ABORT}): control ID 1 "
            "with that state and throttle 0 (and, from protocol version 4, ID 6 with state none and "
            "RPM factor 0, then ID 1 again; pump-off after a pump-on).", ""]
    return out


def _zap() -> list:
    out = ["## mightyZAP IR protocol (12Lf)", "",
           "Packets are `FF FF FF ID SIZE CMD P1..Pn CHK` (command) and `FF FF FF ID SIZE ERR P1..Pn "
           "CHK` (feedback); SIZE = n + 2; CHK = 0xFF - ((ID + SIZE + CMD/ERR + P1..Pn) & 0xFF). "
           f"IDs are 0..{zap.MAX_ID}; {zap.BROADCAST} (0x{zap.BROADCAST:02X}) is broadcast and never answered.",
           "", "### Instructions", ""]
    when = {"always": "every return mode", "load": "return modes 1 and 2", "all": "return mode 2"}
    out += _table(("code", "name", "command", "answered in", "parameters", "meaning"),
                  [(f"0x{i.code:02X}", i.name, i.cli, when[i.reply], i.params_help, i.help)
                   for i in zap.INSTRUCTIONS])
    out += ["### Registers", "",
            "Access R (read-only) or RW; memory NV (stored, survives power-off; writes need the "
            "STORED permission: consent on a real port) or V (volatile). The range column is each "
            "register's documented domain: a range, choices, or bits; a value outside it is refused.", ""]
    out += _table(("address", "name", "size", "access", "memory", "default", "range", "unit", "meaning"),
                  [(f"0x{r.address:02X}", r.name, r.size, r.access, r.memory,
                    "" if r.default is None else r.default, r.describe_range(),
                    (f"{r.scale:g} {r.unit}" if r.scale != 1 else r.unit), r.help) for r in zap.REGISTERS])
    out += ["Addresses IR Robot's Arduino header names beyond the map (read raw by name, not part of "
            "the map a dump reads; writing them needs the UNDOCUMENTED permission):", ""]
    out += _table(("address", "name", "access", "meaning"),
                  [(f"0x{r.address:02X}", r.name, r.access, r.help) for r in zap.UNDOCUMENTED_REGISTERS])
    out += _permissions()
    out += ["### Feedback error bits", ""]
    out += _table(("bit", "name", "meaning"), [(b, n, zap.ERROR_TEXT.get(n, "")) for b, n in
                                              sorted(zap.ERROR_BITS.items())])
    out += ["### Baud-rate codes (register baud-rate)", ""]
    out += _table(("code", "baud"), [(c, b) for c, b in sorted(zap.BAUD_CODES.items())])
    return out


def _permissions() -> list:
    from ..codec import permissions as P

    out = ["### Permissions", "",
           "What sending a frame needs, decided on the typed frame (`zap.Command.needs()`, "
           "`zk.ControlFrame.needs()`) and enforced where every frame goes out. Consent guards real "
           "hardware (a simulator waives it; the command line: --yes); force marks a deliberate act "
           "(needed everywhere; the command line: --force). "
           f"Identity registers: {', '.join(zap.IDENTITY_REGISTERS)}.", ""]
    out += _table(("permission", "kind", "what needs it"),
                  [(p.name, "consent" if p & P.CONSENT else "force", P.WHAT[p]) for p in P.members(P.ALL)])
    return out


def render() -> str:
    """The whole reference as Markdown."""
    lines = ["# Protocol reference", "",
             "Generated by `python -m zkzap.docs all` from the tables in `cli/zkzap/codec/zk.py` and "
             "`cli/zkzap/codec/zap.py`: what zkzap encodes, decodes and checks. Do not edit by hand. "
             "Where the specifications are silent or wrong, [the decisions](decisions.md) say what zkzap "
             "does.", ""]
    lines += _zk() + _zap()
    return "\n".join(lines).rstrip("\n") + "\n"


def generate(outdir) -> list:
    """Write ``OUTDIR/protocol.md``; returns the paths written."""
    os.makedirs(outdir, exist_ok=True)
    path = os.path.join(outdir, "protocol.md")
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(render())
    return [path]
