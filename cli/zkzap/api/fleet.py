"""Actuator fleets: backup documents, diffs, apply plans with minimal writes, guided ID setup.

A **backup document** holds every readable register of every actuator of a bus, grouped by ID,
with the model number, firmware version and baud rate each answered at, the time, and the
zkzap version. Registers sit in three sections named after their memory (from the register
table, :data:`zkzap.codec.zap.REGISTERS`): ``stored`` (NV: survives power-off), ``volatile``
(V: reset at power-on) and ``read-only`` (kept for reference, never written)::

    {"format": "zkzap-fleet/1", "zkzap": "0.1.0", "time": "2026-12-01T10:00:00Z",
     "actuators": {"1": {"model": 3148, "firmware": 20, "baud": 57600,
                         "stored": {"id": 1, "baud-rate": 32, ...},
                         "volatile": {"force-on-off": 1, ...},
                         "read-only": {"model-number": 3148, ...}}}}

Values are raw register values (the units of ``zap registers``). The same document is written
as JSON, TOML or YAML, chosen by the file's suffix (:func:`dump_document`,
:func:`read_document`); TOML and YAML are written by this module (the block mappings of
scalars a person edits), and every file is read by :mod:`zkzap.api.documents`: JSON by the
standard library, TOML by ``tomllib`` (``tomli`` before Python 3.11), YAML by PyYAML's safe
loader (the ``yaml`` extra), a key given twice refused in all three.

A file that cannot be parsed is refused naming ``FILE:LINE`` (``fleet.yaml:7: key 'acceleration'
is given twice``); every check of a parsed document is strict and names ``FILE`` and the key
(``fleet.json: actuators.1.stored.speed-limt: unknown register``): :class:`DocumentError`, a
usage error.

:func:`plan` computes the writes that make an actuator match a document entry, skipping
every write that would change nothing (stored writes wear the actuator's memory), and
:func:`execute` carries them out with a read-back each; its ``done`` list says exactly which
writes happened when it is interrupted. Bus reads go through :class:`Procedures`, the one
place that knows how an actuator is found and read.

Nothing here imports click or rich.
"""

from __future__ import annotations

import json
import os
import re
import time

from ..codec import zap
from ..codec.fields import FieldValueError
from ..errors import CheckFailed, UsageError, did_you_mean
from . import documents
from .documents import DocumentError

#: The format a backup is written in: ``zkzap-fleet/2`` names the protocol family and the
#: register map (``protocol``, ``map``); a ``zkzap-fleet/1`` file (before Modbus) is read as
#: IR actuators of the 12Lf map.
FORMAT = "zkzap-fleet/2"
#: Every format this version reads.
FORMATS = ("zkzap-fleet/1", FORMAT)
SETUP_FORMAT = "zkzap-setup/1"
SECTIONS = ("stored", "volatile", "read-only")
#: Entry keys besides the sections.
META_KEYS = ("model", "firmware", "baud", "time", "errors", "motion")
#: Settings an apply never writes unless named with ``only`` and ``force``: they change how
#: (or whether) the actuator can be reached and answers.
PROTECTED = ("id", "baud-rate", "protocol-type", "feedback-return-mode")
#: File suffixes and their formats.
SUFFIXES = documents.SUFFIXES

REG = zap.REGISTER_BY_NAME


def map_named(protocol: str, model=None, given=None):
    """The register map of a document's ``protocol`` and ``map`` (its model's name): ``given``
    (a :class:`~zkzap.codec.regmap.RegisterMap`, the command's ``--map``) when its model and
    protocol are those, else the shipped map of that model; None when zkzap ships none."""
    from ..codec.regmap import BUILTIN, builtin, default_map

    if given is not None and given.protocol == protocol and (model is None or given.model == model):
        return given
    if model is None:
        return default_map(protocol)
    key = f"{str(model).lower()}-{protocol}"
    return builtin(key) if key in BUILTIN else None


def regmap_of(bus):
    """The register map of the actuators on ``bus`` (a link): the Modbus link's, or the 12Lf's
    IR map."""
    m = getattr(bus, "regmap", None)
    return m if m is not None else zap.MAP


def all_ids(regmap) -> list:
    """Every unicast ID of the map's protocol: 0..253 on IR, 1..247 on Modbus RTU."""
    if regmap.protocol == "modbus":
        from ..codec import modbus

        return list(range(1, modbus.MAX_ID + 1))
    return list(range(zap.MAX_ID + 1))


def check_ident(regmap, value) -> int:
    """An actuator ID of the map's protocol (FieldValueError otherwise)."""
    if regmap.protocol == "modbus":
        from ..codec import modbus

        return modbus.check_id(value, allow_broadcast=False)
    return zap.check_id(value, allow_broadcast=False)


def describe_map(regmap) -> str:
    """``IR (12Lf)``, ``Modbus RTU (17Lf)``: a map's protocol and model, as messages name them."""
    return f"{'Modbus RTU' if regmap.protocol == 'modbus' else 'IR'} ({regmap.model})"


def same_map(regmap, other, name="the file", bus="the bus") -> None:
    """UsageError when a document of map ``regmap`` meets a bus (or document) of map ``other``:
    the protocols' maps differ in addresses, ranges and baud codes (a 12Lf position is 0..4095, a
    17Lf one 0..10000), so a value copied by register name could be a wrong number."""
    if regmap is other or (regmap.protocol, regmap.model) == (other.protocol, other.model):
        return
    hint = (f"; --protocol {regmap.protocol} talks to it" if regmap.protocol != other.protocol
            else "; --map FILE gives another model's map")
    raise UsageError(f"{name} holds {describe_map(regmap)} actuators but {bus} is {describe_map(other)}: "
                     f"their register maps differ (addresses, ranges, baud codes), so no value is copied "
                     f"across{hint}", protocol=regmap.protocol, other=other.protocol)


def section_of(reg) -> str:
    """The document section a register belongs to: ``read-only`` for every register that is not
    written (the 17Lf's map gives the memory of some: its model number is NV, its present
    position V), else ``stored`` (NV) or ``volatile`` (V)."""
    if not reg.writable:
        return "read-only"
    return {"NV": "stored", "V": "volatile", "": "read-only"}[reg.memory]


def unit_of(reg) -> str:
    """The unit of a raw value: ``0.1 V`` for a scaled register, the register's unit, or ``""``."""
    if reg.scale != 1:
        return f"{reg.scale:g} {reg.unit}"
    return reg.unit


# -- reading a bus ---------------------------------------------------------------------------

from .zap import map_blocks  # noqa: E402 - one definition: the Load Data blocks that cover the map


class Procedures:
    """How actuators are found and read: ``find`` (Echo to each ID) and ``read_map`` (every
    register in as few Load Data reads as the map has blocks). The single place a fleet
    operation touches these procedures, so they can be pointed at another implementation."""

    @staticmethod
    def discover(bus, ids, bauds=None, *, retries=2):
        """Scan records (``id``, ``baud``, ``model``, ``firmware``, ``return_mode``, ``status``,
        ``errors``) of the actuators among ``ids`` at each of ``bauds`` (default: the bus's),
        found as ``zap scan`` finds them (:mod:`zkzap.link.zap_scan`): a fast first pass whose
        doubts (something late or garbled on the line) are probed again in quick rounds and
        what stays in doubt asked with the whole window. Two
        actuators sharing an ID give status ``duplicate`` or ``garbled``. The bus is left at the
        last baud rate."""
        from ..link.zap_scan import scan

        return [ev[1] for ev in scan(bus, list(ids), list(bauds or [bus.baud]), retries=retries)
                if ev[0] == "record"]

    @staticmethod
    def find(bus, ids, *, retries=2):
        """IDs of ``ids`` that answer at the bus's baud rate (see :meth:`discover`), and those
        whose replies collide (two actuators answering to one ID): ``(found, garbled)``."""
        found, garbled = [], []
        for rec in Procedures.discover(bus, ids, retries=retries):
            (garbled if rec["status"] in SHARED else found).append(rec["id"])
        return found, garbled

    @staticmethod
    def read_map(bus, ident):
        """``({register name: raw}, error bits)`` of one actuator: every register of the bus's
        map (``regmap_of(bus)``), in as few reads as it has blocks. The error bits are the replies'
        on IR, the hardware-error register on Modbus RTU (whose replies carry none; an exception
        reply raises)."""
        regmap = regmap_of(bus)
        values, error = {}, 0
        modbus = regmap.protocol == "modbus"
        if modbus:
            from .zap_modbus import runs

            blocks = runs(regmap)
        else:
            blocks = map_blocks()
        for address, length in blocks:
            reply, regs = bus.read_registers(ident, address, length, check=modbus)
            error |= 0 if modbus else reply.error
            for reg, raw in regs:
                if regmap.by_address.get(reg.address) is reg:
                    values[reg.name] = raw
        if modbus:
            error = values.get("hardware-error", 0)
        return values, error


#: Scan statuses of an ID that two actuators answer to.
SHARED = ("duplicate", "garbled")

PROCEDURES = Procedures()


class SharedId(CheckFailed):
    """Two actuators answer to one ID (exit status 1): a fleet operation refuses the bus."""


def refuse_shared(records) -> None:
    """Raise :class:`SharedId` naming every ID (and baud rate) of ``records`` (scan records) that
    two actuators answer to."""
    shared = [r for r in records if r["status"] in SHARED]
    bauds = {}
    for r in records:
        bauds.setdefault(r["id"], []).append(r["baud"])
    twice = {i: b for i, b in bauds.items() if len(b) > 1}
    if twice:
        where = "; ".join(f"ID {i} answers at {' and '.join(map(str, b))} baud" for i, b in sorted(twice.items()))
        raise SharedId(f"{where}: two actuators with one ID", ids=sorted(twice), shared=True)
    if shared:
        where = ", ".join(f"ID {r['id']} at {r['baud']} baud" for r in shared)
        raise SharedId(f"{where}: two actuators answer to {'this ID' if len(shared) == 1 else 'these IDs'} "
                       "(their replies collide)", ids=[r["id"] for r in shared], shared=True)


def refuse_census(bus, ids) -> None:
    """Raise :class:`SharedId` when more replies than were due come from any of ``ids`` (two
    actuators with one ID whose replies do not meet, so no scan sees them garbled; see
    :meth:`zkzap.link.zap_bus.ZapBus.census`): nothing of such an ID is read as one actuator's."""
    ids = list(ids)
    census = getattr(bus, "census", None)
    if not ids or census is None:
        return
    shared = [i for i, seen in census(ids).items() if seen == "shared"]
    if shared:
        where = ", ".join(f"ID {i}" for i in shared)
        raise SharedId(f"{where} at {bus.baud} baud: two replies came where one was due (two actuators seem to "
                       f"answer to {'this ID' if len(shared) == 1 else 'these IDs'}, or the line is faulty)",
                       ids=shared, shared=True)


def read_fleet(bus, records, *, procedures=PROCEDURES, on_actuator=None) -> dict:
    """A backup document of the actuators of ``records`` (as :meth:`Procedures.discover` gives
    them), each read at the baud rate it answered at."""
    doc = None
    for baud in dict.fromkeys(r["baud"] for r in records):
        if bus.baud != baud:
            bus.set_baud(baud)
        part = read_bus(bus, [r["id"] for r in records if r["baud"] == baud], procedures=procedures,
                        on_actuator=on_actuator)
        if doc is None:
            doc = part
        else:
            doc["actuators"].update(part["actuators"])
    return doc


def now_iso() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def error_names(regmap, error: int) -> list:
    """The names of the error bits ``error``: the feedback packet's on IR, the hardware-error
    register's on Modbus RTU."""
    reg = regmap.by_name.get("hardware-error") if regmap.protocol == "modbus" else None
    if reg is None or not reg.bits:
        return zap.error_names(error)
    return reg.bit_names(error)


def entry_from_values(values: dict, *, baud, error=0, when=None, regmap=None) -> dict:
    """A document entry for one actuator from its register values (of ``regmap``, default the
    12Lf's)."""
    regmap = regmap or zap.MAP
    entry = {"model": values.get("model-number"), "firmware": values.get("firmware-version"), "baud": baud,
             "time": when or now_iso()}
    if error:
        entry["errors"] = error_names(regmap, error)
    for section in SECTIONS:
        entry[section] = {}
    for reg in regmap.registers:
        if reg.name in values:
            entry[section_of(reg)][reg.name] = values[reg.name]
    return entry


def read_bus(bus, ids, *, procedures=PROCEDURES, on_actuator=None) -> dict:
    """A backup document of actuators ``ids`` on ``bus`` (each must answer)."""
    from .. import __version__

    regmap = regmap_of(bus)
    doc = {"format": FORMAT, "zkzap": __version__, "time": now_iso(), "protocol": regmap.protocol,
           "map": regmap.model, "actuators": {}}
    refuse_census(bus, ids)
    for ident in ids:
        values, error = procedures.read_map(bus, ident)
        doc["actuators"][str(ident)] = entry_from_values(values, baud=bus.baud, error=error, regmap=regmap)
        if on_actuator is not None:
            on_actuator(ident, doc["actuators"][str(ident)])
    return doc


# -- documents: validation -------------------------------------------------------------------

class Entry:
    """One checked actuator of a document: ``ident``, ``model``, ``firmware``, ``baud``,
    ``values`` ({Register: raw}, every section), ``motion`` (its stroke and calibration, see
    :mod:`zkzap.api.units`; None when the file gives none) and ``regmap`` (the register map of
    its protocol and model: the 12Lf's IR map, the 17Lf's Modbus map, or a user's)."""

    __slots__ = ("ident", "model", "firmware", "baud", "values", "motion", "regmap")

    def __init__(self, ident, model, firmware, baud, values, motion=None, regmap=None):
        self.ident, self.model, self.firmware, self.baud, self.values = ident, model, firmware, baud, values
        self.motion = motion
        self.regmap = regmap or zap.MAP

    def settings(self, section):
        return {r: v for r, v in self.values.items() if section_of(r) == section}


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


TOP_KEYS = ("format", "zkzap", "time", "port", "protocol", "map", "actuators", "buses")


def document_map(doc, name="document", regmap=None):
    """The register map a parsed document's actuators are of: its ``protocol`` (default ``ir``)
    and ``map`` (the model's name; default the protocol's shipped model), ``regmap`` (a user's map
    file, ``--map``) when it is that model. DocumentError when zkzap has no such map."""
    from ..codec.regmap import PROTOCOLS

    def fail(key, text):
        raise DocumentError(f"{name}: {key}: {text}")

    if not isinstance(doc, dict):
        return zap.MAP
    protocol = doc.get("protocol", "ir")
    if protocol not in PROTOCOLS:
        fail("protocol", f"{protocol!r}; allowed {', '.join(PROTOCOLS)}")
    model = doc.get("map")
    if model is not None and not isinstance(model, str):
        fail("map", f"{model!r} is not a model's name (like 12Lf or 17Lf)")
    if doc.get("format") == FORMATS[0] and (protocol != "ir" or model not in (None, zap.MAP.model)):
        fail("protocol", f"a {FORMATS[0]} file holds IR actuators of the {zap.MAP.model} only; use {FORMAT}")
    found = map_named(protocol, model, regmap)
    if found is None:
        fail("map", f"zkzap ships no {protocol} map of the {model}; give its map file with --map FILE")
    return found


def check_document(doc, name="document", regmap=None, *, _buses_out=None) -> dict:
    """{ID: :class:`Entry`} from a parsed document; DocumentError naming ``name`` and the key.
    Its register names, IDs and baud rates are checked against the map of its protocol and
    model (:func:`document_map`; ``regmap``: a user's map the document may name)."""
    def fail(key, text):
        raise DocumentError(f"{name}: {key}: {text}" if key else f"{name}: {text}")

    if not isinstance(doc, dict):
        fail("", f"not a zkzap fleet document (expected an object with format {FORMAT!r})")
    fmt = doc.get("format")
    if fmt not in FORMATS:
        fail("format", f"{fmt!r} is not {FORMAT!r}" + (f" (nor {FORMATS[0]!r})" if fmt is not None else "")
             if fmt is not None else f"missing; expected {FORMAT!r}")
    for key in doc:
        if key not in TOP_KEYS:
            fail(key, f"unknown key; allowed {', '.join(TOP_KEYS)}")
    regmap = document_map(doc, name, regmap)
    per_bus = {}
    if doc.get("buses") is not None:
        from .buses import check_buses

        check_buses(doc["buses"], fail)
        for bus, spec in doc["buses"].items():
            if spec.get("actuators") is not None:
                per_bus[bus] = check_entries(spec["actuators"], f"buses.{bus}.actuators", regmap, fail)
                listed = sorted(per_bus[bus])
                if sorted(spec["ids"]) != listed:
                    fail(f"buses.{bus}.ids", f"{sorted(spec['ids'])} are not the IDs of its actuators ({listed})")
    actuators = doc.get("actuators")
    if actuators is None and per_bus:
        out = {}                              # every actuator is its bus's (buses.NAME.actuators)
    else:
        out = check_entries(actuators, "actuators", regmap, fail)
    if _buses_out is not None:
        _buses_out.update(per_bus)
    return out


def bus_documents(doc, name="document", regmap=None) -> dict:
    """``{bus name: {ID: Entry}}`` of a parsed document whose buses carry their actuators
    (``buses.NAME.actuators``, as ``zap backup`` of several buses writes them: an ID is that
    bus's), checked as :func:`check_document` checks a document; ``{}`` when none does."""
    per_bus: dict = {}
    check_document(doc, name, regmap, _buses_out=per_bus)
    return per_bus


def check_entries(actuators, prefix, regmap, fail) -> dict:
    """{ID: Entry} of one bus's ``actuators`` object (``prefix``: its key in the document)."""
    by_name = regmap.by_name
    bauds = sorted(regmap.baud_codes.values())
    if not isinstance(actuators, dict) or not actuators:
        fail(prefix, "missing or empty; expected an object of actuators by ID")
    out = {}
    for key, entry in actuators.items():
        where = f"{prefix}.{key}"
        ids = all_ids(regmap)
        try:
            ident = check_ident(regmap, str(key)) if re.fullmatch(r"\s*\d+\s*", str(key)) else None
        except FieldValueError:
            ident = None
        if ident is None:
            fail(where, f"{key!r} is not an actuator ID; allowed {ids[0]}..{ids[-1]}")
        if ident in out:
            fail(where, f"ID {ident} is given twice")
        if not isinstance(entry, dict):
            fail(where, "expected an object with model, firmware, baud and the register sections")
        for k in entry:
            if k not in META_KEYS and k not in SECTIONS:
                fail(f"{where}.{k}", f"unknown key; allowed {', '.join(META_KEYS + SECTIONS)}")
        for k in ("model", "firmware", "baud"):
            v = entry.get(k)
            if v is not None and not _is_int(v):
                fail(f"{where}.{k}", f"{v!r} is not an integer")
        baud = entry.get("baud")
        if baud is not None and baud not in bauds:
            fail(f"{where}.baud", f"{baud} is not an actuator baud rate; allowed {', '.join(map(str, bauds))}")
        values = {}
        for section in SECTIONS:
            regs = entry.get(section, {})
            if regs is None:
                continue
            if not isinstance(regs, dict):
                fail(f"{where}.{section}", "expected an object of register names and values")
            for rname, value in regs.items():
                rkey = f"{where}.{section}.{rname}"
                reg = by_name.get(str(rname))
                if reg is None:
                    see = "'zap registers'" + (" --protocol modbus" if regmap.protocol == "modbus" else "")
                    fail(rkey, "unknown register" + did_you_mean(rname, by_name, otherwise=f"; see {see}"))
                if section_of(reg) != section:
                    fail(rkey, f"{reg.name} is a {section_of(reg)} register, not {section}")
                if not _is_int(value):
                    fail(rkey, f"{value!r} is not an integer")
                if section == "read-only":
                    if not 0 <= value < 1 << (8 * reg.size):
                        fail(rkey, f"{value} does not fit {reg.size} byte{'s' if reg.size > 1 else ''}")
                else:
                    try:
                        reg.check(value)
                    except FieldValueError as e:
                        fail(rkey, str(e).split(": ", 1)[-1])
                values[reg] = value
        stored_id = values.get(by_name.get("id"))
        if stored_id is not None and stored_id != ident:
            fail(f"{where}.stored.id", f"{stored_id} differs from the actuator's key {ident}")
        motion = entry.get("motion")
        if motion is not None:
            from .units import check_motion

            check_motion(motion, f"{where}.motion", fail)
        out[ident] = Entry(ident, entry.get("model"), entry.get("firmware"), baud, values, motion, regmap)
    return out


# -- documents: files ------------------------------------------------------------------------

def format_of(path: str) -> str:
    ext = os.path.splitext(path)[1].lower()
    fmt = SUFFIXES.get(ext)
    if fmt is None:
        raise UsageError(f"{path}: unknown file type {ext or '(no suffix)'!r}; use .json, .toml or .yaml")
    return fmt


def dumps(doc: dict, fmt: str) -> str:
    if fmt == "json":
        return json.dumps(doc, indent=2) + "\n"
    if fmt == "toml":
        return _toml(doc)
    if fmt == "yaml":
        return _yaml(doc)
    raise UsageError(f"format: {fmt!r}; allowed json, toml, yaml")


def dump_document(doc: dict, path: str, fmt=None) -> None:
    """Write ``doc`` to ``path`` in ``fmt`` (default: the one its suffix names), whole
    (:func:`zkzap.outfile.write_whole`: atomically onto a regular file, keeping its mode; a
    failed or interrupted write leaves any existing file as it was)."""
    from ..outfile import write_whole

    write_whole(path, dumps(doc, fmt or format_of(path)), what="output")


def loads(text: str, fmt: str, name: str):
    """The parsed document ``text`` in ``fmt`` (json, toml, yaml); DocumentError naming
    ``name`` and the line."""
    return documents.loads(text, fmt, name)


def read_document(path: str, regmap=None) -> dict:
    """{ID: Entry} from a backup file (``-``: JSON on stdin); ``regmap``: a user's map the file
    may name (see :func:`check_document`)."""
    fmt = "json" if path == "-" else format_of(path)
    doc, name = documents.read(path, "fleet", fmt)
    return check_document(doc, name, regmap)


def map_of(entries: dict):
    """The register map of checked entries ({ID: Entry}: one document's, so one map)."""
    return next(iter(entries.values())).regmap if entries else zap.MAP


_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(k) -> str:
    k = str(k)
    return k if _BARE.match(k) else json.dumps(k)


def _toml_value(v) -> str:
    if v is True or v is False:
        return "true" if v else "false"
    if _is_int(v) or isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(str(v))


def _toml(doc, prefix=()) -> str:
    lines = []
    scalars = {k: v for k, v in doc.items() if not isinstance(v, dict) and v is not None}
    tables = {k: v for k, v in doc.items() if isinstance(v, dict)}
    if prefix and (scalars or not tables):
        lines.append("[" + ".".join(_toml_key(p) for p in prefix) + "]")
    for k, v in scalars.items():
        lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in tables.items():
        out += ("\n" if out else "") + _toml(v, prefix + (k,))
    return out


def _yaml_scalar(v) -> str:
    if v is None:
        return "null"
    if v is True or v is False:
        return "true" if v else "false"
    if _is_int(v) or isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_yaml_scalar(x) for x in v) + "]"
    return json.dumps(str(v))


def _yaml(doc, indent=0) -> str:
    out = []
    pad = "  " * indent
    for k, v in doc.items():
        key = str(k) if _BARE.match(str(k)) and not str(k).isdigit() else json.dumps(str(k))
        if isinstance(v, dict):
            out.append(f"{pad}{key}:" + (" {}" if not v else ""))
            if v:
                out.append(_yaml(v, indent + 1).rstrip("\n"))
        else:
            out.append(f"{pad}{key}: {_yaml_scalar(v)}")
    return "\n".join(out) + "\n"


# -- diff ------------------------------------------------------------------------------------

DIFF_COLUMNS = ["id", "register", "address", "memory", "a", "b", "unit", "equal"]
#: Which sections a diff compares: ``stored`` (the default: settings that survive power-off),
#: ``settings`` (stored and volatile), ``all`` (read-only values too).
COMPARE = {"stored": ("stored",), "settings": ("stored", "volatile"), "all": SECTIONS}


def diff(a: dict, b: dict, *, compare="stored", ids=None, everything=False) -> list:
    """Rows (id, register, address, memory, a, b, unit, equal) comparing two {ID: Entry}. An
    actuator present on one side only gives one row with register ``"(actuator)"``. Two sides of
    different register maps (protocols or models) are refused (:func:`same_map`)."""
    sections = COMPARE[compare]
    regmap = map_of(a) if a else map_of(b)
    if a and b:
        same_map(map_of(a), map_of(b), "A", "B")
    rows = []
    wanted = sorted(set(a) | set(b)) if ids is None else list(ids)
    for ident in wanted:
        ea, eb = a.get(ident), b.get(ident)
        if ea is None or eb is None:
            rows.append({"id": ident, "register": "(actuator)", "address": None, "memory": None,
                         "a": "present" if ea else "absent", "b": "present" if eb else "absent", "unit": "",
                         "equal": False})
            continue
        for reg in regmap.registers:
            if section_of(reg) not in sections:
                continue
            va, vb = ea.values.get(reg), eb.values.get(reg)
            if va is None and vb is None:
                continue
            equal = va == vb
            if equal and not everything:
                continue
            rows.append({"id": ident, "register": reg.name, "address": reg.address, "memory": reg.memory or "R",
                         "a": va, "b": vb, "unit": unit_of(reg), "equal": equal})
    return rows


# -- apply -----------------------------------------------------------------------------------

class Write:
    """One planned register write: on bus ID ``target`` (from the document's ``source``),
    ``register`` from ``old`` (the bus's value now) to ``new``."""

    __slots__ = ("target", "source", "register", "old", "new", "status", "read_back", "errors", "note")

    def __init__(self, target, source, register, old, new):
        self.target, self.source, self.register, self.old, self.new = target, source, register, old, new
        self.status = "planned"
        self.read_back = None
        self.errors = []
        self.note = ""

    def record(self) -> dict:
        reg = self.register
        return {"id": self.target, "source": self.source, "register": reg.name, "address": reg.address,
                "memory": reg.memory, "old": self.old, "new": self.new, "unit": unit_of(reg),
                "status": self.status, "read_back": self.read_back, "errors": list(self.errors),
                "note": self.note}

    def __repr__(self):
        return f"Write(ID {self.target}: {self.register.name} {self.old} -> {self.new}, {self.status})"


PLAN_COLUMNS = ["id", "source", "register", "address", "memory", "old", "new", "unit", "status", "read_back",
                "errors", "note"]


def registers_option(names, what, regmap=None) -> list:
    """Registers of ``regmap`` (default the 12Lf's) named in ``--only``/``--skip`` (UsageError
    for an unknown or read-only one)."""
    regmap = regmap or zap.MAP
    out = []
    for n in names or ():
        try:
            reg = regmap.register(n)
        except FieldValueError as e:
            raise UsageError(f"{what}: {e}") from None
        if regmap.by_address.get(reg.address) is not reg:
            raise UsageError(f"{what}: {n!r} is not a register of the map; see 'zap registers'")
        if not reg.writable:
            raise UsageError(f"{what}: {reg.name} is read-only; it is never written")
        if reg not in out:
            out.append(reg)
    return out


def assignments(entries: dict, *, ids=None, mapping=None, to=None) -> list:
    """(document ID, bus ID) pairs: ``ids`` selects document IDs (default: all); ``mapping``
    ({old: new}) sends document ID old to bus ID new; ``to`` clones the one selected document
    actuator onto every bus ID listed. UsageError for IDs the document lacks or clashes."""
    chosen = sorted(entries) if ids is None else list(ids)
    for i in chosen:
        if i not in entries:
            raise UsageError(f"--ids: ID {i} is not in the file; it has {', '.join(map(str, sorted(entries)))}")
    mapping = dict(mapping or {})
    for old in mapping:
        if old not in entries:
            raise UsageError(f"--id-map: ID {old} is not in the file; it has {', '.join(map(str, sorted(entries)))}")
        if old not in chosen:
            chosen.append(old)
    if to is not None:
        if mapping:
            raise UsageError("--to and --id-map do not go together: --to clones one actuator onto many")
        if len(chosen) != 1:
            raise UsageError(f"--to clones one actuator, but {len(chosen)} are selected "
                             f"({', '.join(map(str, chosen))}); choose one with --ids")
        return [(chosen[0], t) for t in to]
    pairs = [(i, mapping.get(i, i)) for i in chosen]
    targets = [t for _, t in pairs]
    dup = sorted({t for t in targets if targets.count(t) > 1})
    if dup:
        t = dup[0]
        sources = [f"ID {i} ({'--id-map ' + str(i) + ':' + str(t) if i in mapping else 'kept as it is'})"
                   for i, target in pairs if target == t]
        unmapped = [i for i in chosen if i not in mapping]
        hint = (f"; an ID of the file that --id-map does not name keeps its own, and without --ids every ID "
                f"of the file ({_ranges(sorted(entries))}) is applied: add --ids {','.join(map(str, mapping))} "
                f"to apply only the mapped ones" if unmapped and ids is None else "")
        raise UsageError(f"--id-map: bus ID {t} would get the settings of two actuators of the file: "
                         f"{' and '.join(sources)}{hint}", bus_id=t)
    return pairs


def plan(entry: Entry, target: int, current: dict, *, only=None, skip=(), force=False) -> tuple:
    """(writes, unchanged): the writes that make bus actuator ``target`` (register values
    ``current``, {name: raw}) match ``entry``'s stored settings, and the volatile ones named in
    ``only``; writes that would change nothing are left out (``unchanged`` counts them).

    id, baud-rate and protocol-type are written only when named in ``only`` and ``force``
    (UsageError when named without ``force``); id and baud-rate go last, since they change
    how the actuator is reached.
    """
    only = list(only) if only else None
    skip = set(skip or ())
    if only is not None:
        for reg in only:
            if reg.name in PROTECTED and not force:
                raise UsageError(f"--only {reg.name}: this changes how the actuator is reached; "
                                 "add --force to write it")
            if reg not in entry.values:
                raise UsageError(f"--only {reg.name}: ID {entry.ident} of the file has no {reg.name}")
            if reg.name == "id" and target != entry.ident:
                raise UsageError(cloned_id(entry.ident, target), source=entry.ident, target=target)
        chosen = [r for r in entry.regmap.registers if r in only]
    else:
        chosen = [r for r in entry.regmap.registers
                  if r.stored and r.writable and r.name not in PROTECTED and r in entry.values]
    if target != entry.ident:                 # a clone: the file's ID is its key, never a setting to copy
        chosen = [r for r in chosen if r.name != "id"]
    writes, unchanged = [], 0
    for reg in chosen:
        if reg in skip:
            continue
        new = entry.values[reg]
        old = current.get(reg.name)
        if old == new:
            unchanged += 1
            continue
        writes.append(Write(target, entry.ident, reg, old, new))
    order = {"feedback-return-mode": 1, "baud-rate": 2, "id": 3}
    writes.sort(key=lambda w: order.get(w.register.name, 0))
    return writes, unchanged


def check_only(only, pairs) -> None:
    """UsageError, before the bus is touched, for ``--only id`` on a clone (a pair whose bus ID is
    not the file's: :func:`cloned_id`)."""
    if only and any(r.name == "id" for r in only):
        for source, target in pairs:
            if source != target:
                raise UsageError(cloned_id(source, target), source=source, target=target)


def cloned_id(source: int, target: int) -> str:
    """Why an apply that sends the file's actuator ``source`` to bus ID ``target`` never writes
    the ``id`` register: it would give ``target`` the ID ``source``."""
    return (f"--only id: the file's ID {source} goes to bus ID {target} (--map or --to), so its id is the "
            f"file's key, not a setting to copy: writing it would give bus ID {target} the ID {source}, "
            f"a second actuator with one ID; 'zap set-id' gives an actuator another ID, checked free first")


def left_out(entries: dict, pairs, current: dict, *, only=None, skip=()) -> list:
    """The differences an apply does not write, so a plan can say so: ``[(target, register,
    bus value, file value, why)]`` with ``why`` ``"protected"`` (id, baud-rate, protocol-type,
    feedback-return-mode: written only when named in ``only``, with force), ``"skipped"`` (in
    ``skip``) or ``"not in --only"``. ``current``: {bus ID: {register name: raw}}. Volatile
    settings are not differences an apply is meant to write (unless named in ``only``)."""
    skip = set(skip or ())
    out = []
    for source, target in pairs:
        entry = entries[source]
        values = current.get(target, {})
        for reg in entry.regmap.registers:
            if not (reg.stored and reg.writable) or reg not in entry.values or (reg.name == "id" and source != target):
                continue                      # (a clone's id is the file's key: never a difference)
            new, old = entry.values[reg], values.get(reg.name)
            if old == new:
                continue
            if only is not None:
                if reg in only and reg not in skip:
                    continue
                why = "skipped" if reg in skip else "not in --only"
            elif reg in skip:
                why = "skipped"
            elif reg.name in PROTECTED:
                why = "protected"
            else:
                continue
            out.append((target, reg, old, new, why))
    return out


_WHY_LEFT_OUT = {
    "protected": "they change how the actuator is reached or answers; --only NAME --force writes them",
    "skipped": "left out by --skip",
    "not in --only": "not named in --only",
}


def describe_left_out(items) -> str:
    """``"2 differences not written: baud-rate (ID 1: 32 on the bus, 16 in the file), ... —
    they change how ..."``: what :func:`left_out` found, by reason."""
    parts = []
    for why in _WHY_LEFT_OUT:
        group = [i for i in items if i[4] == why]
        if not group:
            continue
        shown = ", ".join(f"ID {t} {r.name} ({o} on the bus, {n} in the file)" for t, r, o, n, _ in group[:4])
        if len(group) > 4:
            shown += f" and {len(group) - 4} more"
        parts.append(f"{len(group)} difference{'s' if len(group) != 1 else ''} not written: {shown}: "
                     f"{_WHY_LEFT_OUT[why]}")
    return "; ".join(parts)


def read_entries(bus, ids, *, required=True, procedures=PROCEDURES) -> dict:
    """{ID: Entry} read from the bus (every register of each actuator). ``ids``: IDs, or scan
    records (``id``, ``baud``, as :func:`survey` gives them), each then read at the baud rate it
    answered at. ``required``: every ID must answer (else NoReply); otherwise IDs that do not
    answer an Echo are left out (records were found: they are read)."""
    entries = {}
    refuse_census(bus, [i for i in ids if not isinstance(i, dict)])
    for item in ids:
        if isinstance(item, dict):
            ident = item["id"]
            if bus.baud != item["baud"]:
                bus.set_baud(item["baud"])
        else:
            ident = item
            if not required and bus.ping(ident, retries=1) is None:
                continue
        values, error = procedures.read_map(bus, ident)
        entry = entry_from_values(values, baud=bus.baud, error=error, regmap=regmap_of(bus))
        doc = {"format": FORMAT, "protocol": regmap_of(bus).protocol, "map": regmap_of(bus).model,
               "actuators": {str(ident): entry}}
        entries[ident] = check_document(doc, f"bus ID {ident}", regmap_of(bus))[ident]
    return entries


def survey(bus, ids=None, bauds=None, *, scan=None, retries=2, procedures=PROCEDURES) -> list:
    """Scan records (``id``, ``baud``, ...) of the live bus's actuators, as a fleet operation
    compares or backs them up. Without ``ids`` (every ID of the protocol: 0..253 on IR, 1..247
    on Modbus RTU), at several ``bauds``, or with
    ``scan``, the actuators are found as ``zap scan`` finds them (:meth:`Procedures.discover`),
    and a bus where two actuators answer to one ID is refused (:class:`SharedId`, naming it),
    never read without one of them; otherwise ``ids`` are asked for one by one, an ordinary Echo
    each (one that does not answer is absent)."""
    bauds = list(bauds or [bus.baud])
    if scan is None:
        scan = ids is None or len(bauds) > 1
    if not scan:
        if bus.baud != bauds[0]:
            bus.set_baud(bauds[0])
        return [{"id": i, "baud": bus.baud} for i in ids if bus.ping(i, retries=retries) is not None]
    wanted = list(ids) if ids is not None else all_ids(regmap_of(bus))
    records = procedures.discover(bus, wanted, bauds, retries=retries)
    refuse_shared(records)
    return records


def bus_entries(bus, ids=None, bauds=None, *, scan=None, retries=2, procedures=PROCEDURES) -> dict:
    """{ID: Entry} of the live bus, as ``zap diff`` and the browser console compare it with a
    file: the actuators :func:`survey` finds (every one that answers, without ``ids``: an actuator
    that is only on the bus is in it, so a diff names it), each read whole at the baud rate it
    answered at. A bus where two actuators answer to one ID is refused (:class:`SharedId`)."""
    found = survey(bus, ids, bauds, scan=scan, retries=retries, procedures=procedures)
    return read_entries(bus, found, procedures=procedures)


def plan_bus(bus, entries: dict, pairs, *, name="the file", only=None, skip=(), force=False, on_mismatch=None,
             procedures=PROCEDURES) -> tuple:
    """(writes, unchanged, current) that make the bus match ``entries`` for each (document ID,
    bus ID) of ``pairs`` (see :func:`assignments`): every target is read
    (``current``: {bus ID: {register name: raw}}) and planned (:func:`plan`). A target of another
    model or firmware than its entry raises UsageError unless ``force`` (then
    ``on_mismatch(text)`` is told); ``name`` names the document in messages."""
    current, writes, unchanged = {}, [], 0
    if entries:
        same_map(map_of(entries), regmap_of(bus), name)
    for source, target in pairs:
        values, _ = procedures.read_map(bus, target)
        current[target] = values
        entry = entries[source]
        mismatch = identity_mismatch(entry, values)
        if mismatch:
            text = f"ID {target} is {mismatch} (ID {source} in {name})"
            if not force:
                raise UsageError(f"{text}; pass --force to apply it anyway")
            if on_mismatch is not None:
                on_mismatch(text)
        w, u = plan(entry, target, values, only=only, skip=skip, force=force)
        writes += w
        unchanged += u
    return writes, unchanged, current


def identity_mismatch(entry: Entry, current: dict):
    """A sentence when the bus actuator's model or firmware differs from the entry's, else None."""
    problems = []
    model, fw = current.get("model-number"), current.get("firmware-version")
    if entry.model is not None and model is not None and model != entry.model:
        problems.append(f"model 0x{model:04X}, the file's 0x{entry.model:04X}")
    if entry.firmware is not None and fw is not None and fw != entry.firmware:
        problems.append(f"firmware {fw}, the file's {entry.firmware}")
    return "; ".join(problems) or None


def execute(bus, writes, done: list, *, on_write=None, allow=None) -> None:
    """Carry out ``writes`` in order, each read back; every write whose packet went out is
    appended to ``done`` before its read-back, so after any exception (Ctrl-C, a vanished
    port, a silent actuator) ``done`` says exactly which writes were sent: status
    ``verified`` (read back equal), ``mismatch`` (read back another value) or ``sent`` (the
    read-back did not complete) or ``unverifiable`` (feedback-return-mode 0 never answers a read).
    ``on_write(write)`` is called after each read-back. Each write needs what its packet needs
    (:meth:`zkzap.codec.zap.Command.needs`): the bus's permissions, or ``allow``; every write is
    checked before the first is sent.

    An ``id`` write is made the way ``zap set-id`` makes it (:meth:`zkzap.api.zap.Bus.set_id`):
    the new ID is checked free first (:class:`~zkzap.errors.IdTaken` when another actuator
    answers to it: nothing sent, status ``refused``) and read back from the new ID. A
    ``baud-rate`` write gets a ``note`` saying when the new rate takes effect
    (:func:`baud_note`)."""
    from ..codec.permissions import as_permission

    allow = as_permission(allow)
    modbus = regmap_of(bus).protocol == "modbus"
    for w in writes:
        for frame in (bus.write_frames(w.target, {w.register.name: w.new}) if modbus else
                      [zap.store(w.target, w.register, w.new)]):
            bus.authorize(frame, allow)
    for w in writes:
        reg = w.register
        if reg.name == "id":
            _set_id(bus, w, done)
            if on_write is not None:
                on_write(w)
            continue
        w.status = "sending"
        # (a new feedback-return-mode is that actuator's from now on: the bus keeps it per ID;
        # on Modbus RTU an exception reply raises: the write was refused, not made)
        reply = bus.store(w.target, reg, w.new, check=modbus, allow=allow)
        w.status = "sent"
        done.append(w)
        if reply is not None and reply.error:
            w.errors = reply.errors
        if reg.name == "feedback-return-mode" and w.new == 0:
            w.status = "unverifiable"       # mode 0 never answers Load Data: it cannot be read back
            if on_write is not None:
                on_write(w)
            continue
        line = bus.baud
        if modbus and reg.name == "baud-rate":
            # the 17Lf answers at its new rate right after the reply: read back there, then go on at
            # the rate the other actuators still answer at
            rate = regmap_of(bus).baud_codes.get(w.new)
            bus.set_baud(rate)
            try:
                bus.wait_ready(w.target, within=2.0)
                value, errors = _read_back(bus, w.target, reg)
            finally:
                bus.set_baud(line)
        else:
            # on IR a new baud rate takes effect at the next restart: the stored code reads back at once
            value, errors = _read_back(bus, w.target, reg)
        w.read_back = value
        if errors:
            w.errors = sorted(set(w.errors) | set(errors))
        w.status = "verified" if value == w.new else "mismatch"
        if reg.name == "baud-rate" and w.status == "verified":
            w.note = baud_note(regmap_of(bus), w.target, w.old, w.new, line)
        if on_write is not None:
            on_write(w)


def _read_back(bus, ident, reg) -> tuple:
    """``(value, error names)`` of one register read back: a Load Data on IR (its error bits),
    a read on Modbus RTU (an exception reply raises)."""
    if regmap_of(bus).protocol == "modbus":
        _, regs = bus.read_registers(ident, reg.address, reg.span)
        return regs[0][1], []
    r = bus.load(ident, reg.address, reg.size, check=False)
    return r.value, r.errors


def _set_id(bus, w, done) -> None:
    """An ``id`` write of :func:`execute`, made by the one checked procedure for it."""
    from ..errors import IdTaken
    from .zap import Bus

    w.status = "checking"
    try:
        Bus.over(bus).set_id(w.target, w.new)       # checks the new ID is free, then stores and reads back
    except IdTaken:
        w.status = "refused"                        # nothing was sent
        raise
    except BaseException:
        w.status = "sending"                        # the Store may have gone out
        raise
    done.append(w)
    w.read_back, w.status = w.new, "verified"


def baud_note(regmap, target: int, old, new: int, line: int) -> str:
    """When a stored baud-rate code ``new`` (read back equal) takes effect: an IR actuator (the
    12Lf) keeps answering at the rate it runs at until its next restart; a Modbus RTU one (the
    17Lf) answers at the new rate from the write's reply on (it was read back there)."""
    rate = regmap.baud_codes.get(new)
    if regmap.protocol == "modbus":
        return (f"ID {target}: baud-rate {new} ({rate} baud) written and read back at {rate} baud: the actuator "
                f"answers at {rate} baud now, no longer at {line}")
    was = regmap.baud_codes.get(old) if old is not None else None
    return (f"ID {target}: baud-rate {new} ({rate} baud) stored and read back; the actuator answers at {rate} "
            f"baud from its next restart (power-up, or 'zap restart --id {target}'), at {was or line} baud until "
            "then")


# -- guided ID setup -------------------------------------------------------------------------

class SetupState:
    """The state file of a guided setup: which target IDs are done (and from which ID and baud
    the actuator was found), which were skipped. Saved atomically after every change, so a
    second run resumes where the first stopped."""

    def __init__(self, path, ids):
        self.path = path
        self.ids = list(ids)
        self.done = {}                    # target ID -> record
        self.skipped = []

    @classmethod
    def load(cls, path, ids):
        st = cls(path, ids)
        if not path or not os.path.exists(path):
            return st
        doc, _ = documents.read(path, "setup state")
        if not isinstance(doc, dict) or doc.get("format") != SETUP_FORMAT or not isinstance(doc.get("done"), dict):
            raise UsageError(f"{path}: not a zkzap setup state file (format {SETUP_FORMAT})")
        for key, rec in doc["done"].items():
            if not str(key).isdigit() or not 0 <= int(key) <= zap.MAX_ID or not isinstance(rec, dict):
                raise UsageError(f"{path}: done.{key}: not an actuator ID 0..253 with its record")
            st.done[int(key)] = rec
        skipped = doc.get("skipped", [])
        if not isinstance(skipped, list) or not all(_is_int(i) for i in skipped):
            raise UsageError(f"{path}: skipped: expected a list of IDs")
        st.skipped = list(skipped)
        return st

    def save(self) -> None:
        if not self.path:
            return
        doc = {"format": SETUP_FORMAT, "ids": self.ids, "done": {str(k): v for k, v in sorted(self.done.items())},
               "skipped": sorted(set(self.skipped))}
        from ..outfile import write_whole

        write_whole(self.path, json.dumps(doc, indent=1) + "\n", what="state")

    def pending(self) -> list:
        return [i for i in self.ids if i not in self.done and i not in self.skipped]

    def mark_done(self, target, record) -> None:
        self.done[target] = record
        if target in self.skipped:
            self.skipped.remove(target)
        self.save()

    def mark_skipped(self, target, save=True) -> None:
        if target not in self.skipped:
            self.skipped.append(target)
        if save:
            self.save()

    def redo(self, target, save=True) -> None:
        self.done.pop(target, None)
        if target in self.skipped:
            self.skipped.remove(target)
        if save:
            self.save()


class TwoAnswer(CheckFailed):
    """More than one actuator answered during a setup search (exit status 1)."""


class NotFound(CheckFailed):
    """No actuator answered during a setup search (exit status 1)."""


def find_alone(bus, ids, bauds, *, prefer=(), procedures=PROCEDURES, on_progress=None):
    """(ID, baud) of the one actuator connected: at each baud rate in turn, the IDs in
    ``prefer`` first, then the rest of ``ids``; at the first baud rate where anything answers
    every ID of ``ids`` is asked, and two answers (or a garbled reply: two actuators with one
    ID) raise :class:`TwoAnswer`. :class:`NotFound` when nothing answers at any rate."""
    order = [i for i in prefer if i in ids] + [i for i in ids if i not in prefer]
    for baud in bauds:
        if bus.baud != baud:
            bus.set_baud(baud)
        if on_progress is not None:
            on_progress(baud)
        found, garbled = procedures.find(bus, order)
        if garbled:
            raise TwoAnswer(f"a garbled reply from ID {garbled[0]} at {baud} baud: two actuators answer to "
                            "that ID; connect one actuator alone")
        if len(found) > 1:
            raise TwoAnswer(f"{len(found)} actuators answer at {baud} baud (IDs "
                            f"{', '.join(map(str, found))}); connect one actuator alone")
        if found:
            return found[0], baud
    raise NotFound(f"no actuator answers (IDs {_ranges(ids)} at {', '.join(map(str, bauds))} baud); "
                   "check power and wiring")


_ranges = zap.id_ranges


def setup_one(bus, target, *, found, config=None, on_write=None, procedures=PROCEDURES, baud=None) -> dict:
    """Give the actuator found at ``found`` = (ID, baud) the ID ``target``, apply ``config``
    (an :class:`Entry`: its stored settings except id, baud-rate and protocol-type) and
    verify. Returns the record kept in the state file (with ``warning`` when the actuator's
    model or firmware differs from ``config``'s). The writes need the STORED permission on a
    real port (the bus's).

    ``baud``: the rate every actuator of the setup is brought to, first (before its new ID), by
    ``zap set-baud``'s procedure (:meth:`zkzap.api.zap.Bus.set_baud`: the found ID checked free
    at the new rate, the actuator restarted where the protocol needs it and read back at the new
    rate); the ID is then given at that rate, so it is checked free where the actuator will
    answer. Stopped half-way, the actuator answers at the new rate with its old ID: never two
    actuators with one ID."""
    ident, found_baud = found
    record = {"from_id": ident, "from_baud": found_baud, "baud": found_baud, "writes": 0, "time": now_iso()}
    if bus.baud != found_baud:
        bus.set_baud(found_baud)
    if baud is not None and baud != found_baud:
        from .zap import Bus

        Bus.over(bus).set_baud(ident, baud)     # verified at the new rate; the port is left there
        if bus.baud != baud:
            bus.set_baud(baud)
        record["baud"] = baud
        record["writes"] += 1
    if ident != target:
        from ..errors import IdTaken
        from .zap import Bus

        try:                                  # set-id's procedure: the target checked free, read back
            Bus.over(bus).set_id(ident, target)
        except IdTaken:
            raise TwoAnswer(f"ID {target} answers as well as ID {ident}; connect one actuator alone") from None
        record["writes"] += 1
    got = bus.read(target, regmap_of(bus).by_name["id"], check=False)
    if got != target:
        raise CheckFailed(f"setup: the actuator reads back ID {got}, expected {target}")
    if config is not None:
        values, _ = procedures.read_map(bus, target)
        mismatch = identity_mismatch(config, values)
        if mismatch:
            record["warning"] = f"the actuator is {mismatch}"
        writes, _ = plan(config, target, values)
        done: list = []
        execute(bus, writes, done, on_write=on_write)
        bad = [w for w in done if w.status != "verified"]
        if bad:
            raise CheckFailed(f"setup: ID {target}: {bad[0].register.name} reads back {bad[0].read_back}, "
                              f"expected {bad[0].new}")
        record["writes"] += len(done)
        record["config"] = len(done)
    r = bus.echo(target, check=False)
    record["errors"] = r.errors
    return record


# -- several buses ---------------------------------------------------------------------------
#
# A machine's buses, each worked on its own thread (:func:`zkzap.api.buses.run`): a backup of
# several buses names each (``buses.NAME``: port, baud, ids and its ``actuators``, an ID being that
# bus's), and a diff or an apply matches the file's buses to the live ones by name.

def backup_buses(specs, *, ids=None, bauds=None, scan=None, retries=2, open_bus=None, on_actuator=None) -> dict:
    """A backup document of the buses of ``specs`` (:class:`~zkzap.api.buses.BusSpec`), each read
    on its own thread: on each, the spec's IDs (each must answer), else ``ids``, found as
    :func:`survey` finds them at ``bauds`` (default the spec's rate). ``on_actuator(bus, ID,
    entry)`` is told of each actuator read (from the caller's thread)."""
    from .. import __version__
    from ..errors import NoReply
    from . import buses

    def work(bus, spec, emit, cancel):
        wanted = list(spec.ids) or ids
        found = survey(bus, wanted, bauds or [spec.baud], scan=scan if spec.ids else True, retries=retries)
        missing = sorted(set(wanted or ()) - {r["id"] for r in found}) if spec.ids or ids else []
        if not found or missing:
            raise NoReply(f"bus {spec.name}: no reply from ID{'s' if len(missing) != 1 else ''} "
                          f"{_ranges(missing) if missing else 'any'}", bus=spec.name, ids=missing)
        emit({"doc": read_fleet(bus, found)})

    parts = {}
    for rec in buses.run(specs, work, open_bus=open_bus):
        parts[rec["bus"]] = rec["doc"]
        if on_actuator is not None:
            for key, entry in rec["doc"]["actuators"].items():
                on_actuator(rec["bus"], int(key), entry)
    first = next(iter(parts.values()))
    doc = {"format": FORMAT, "zkzap": __version__, "time": now_iso(), "protocol": first["protocol"],
           "map": first["map"], "buses": {}}
    for spec in specs:
        acts = parts[spec.name]["actuators"]
        doc["buses"][spec.name] = {"port": spec.port, "baud": spec.baud, "ids": sorted(int(k) for k in acts),
                                   "actuators": acts}
    return doc


def match_buses(per_bus: dict, ports: dict, specs, name="the file") -> dict:
    """``{live bus name: {ID: Entry}}``: for each live bus of ``specs`` the file's bus of its name,
    or of its port (``ports``: the file's {bus name: port}); UsageError for a live bus the file
    does not have."""
    out = {}
    for spec in specs:
        key = spec.name if spec.name in per_bus else next((n for n, p in ports.items() if p == spec.port
                                                            and n in per_bus), None)
        if key is None:
            raise UsageError(f"{name} has no bus {spec.name!r} with its actuators (it has "
                             f"{', '.join(map(repr, per_bus)) or 'none'})", bus=spec.name)
        out[spec.name] = per_bus[key]
    return out


def read_bus_document(path: str, regmap=None) -> tuple:
    """``({bus name: {ID: Entry}}, {bus name: port}, name)`` of a backup of several buses
    (``regmap``: the map of a model zkzap does not ship, as :func:`read_document`)."""
    fmt = "json" if path == "-" else format_of(path)
    doc, name = documents.read(path, "fleet", fmt)
    return bus_documents(doc, name, regmap), bus_ports(doc), name


def bus_ports(doc) -> dict:
    """{bus name: port} of a parsed document's buses."""
    return {n: b.get("port") for n, b in (doc.get("buses") or {}).items()}


def diff_buses(a: dict, b: dict, **kw) -> list:
    """Rows of :func:`diff` with ``bus`` first, comparing ``{bus: {ID: Entry}}`` bus by bus (a
    bus on one side only: each of its actuators a row ``(actuator)``)."""
    rows = []
    for bus in list(a) + [n for n in b if n not in a]:
        for row in diff(a.get(bus, {}), b.get(bus, {}), **kw):
            rows.append(dict({"bus": bus}, **row))
    return rows


def live_buses(specs, *, ids=None, bauds=None, retries=2, open_bus=None) -> dict:
    """``{bus name: {ID: Entry}}`` of the live buses of ``specs``, each read on its own thread as
    :func:`bus_entries` reads one bus (``ids``: per bus name, the IDs to ask; default every one
    that answers)."""
    from . import buses

    def work(bus, spec, emit, cancel):
        emit({"entries": bus_entries(bus, (ids or {}).get(spec.name), bauds or [spec.baud], retries=retries)})

    return {rec["bus"]: rec["entries"] for rec in buses.run(specs, work, open_bus=open_bus)}


def apply_buses(specs, per_bus: dict, *, name="the file", only=None, skip=(), force=False, plan_only=False,
                allow=None, open_bus=None, on_mismatch=None):
    """Apply each bus's entries of ``per_bus`` ({bus name: {ID: Entry}}) to the live bus of that
    name, each on its own thread: plan (:func:`plan_bus`), then unless ``plan_only`` execute
    (:func:`execute`, each write read back). Yields ``("write", bus, Write)`` for each write
    planned or made and ``("summary", bus, (unchanged, left out))`` per bus; an error on one
    bus stops the others (and is raised when every thread has ended)."""
    from . import buses

    def work(bus, spec, emit, cancel):
        entries = per_bus[spec.name]
        pairs = assignments(entries)
        writes, unchanged, current = plan_bus(bus, entries, pairs, name=f"{name} (bus {spec.name})", only=only,
                                              skip=skip, force=force, on_mismatch=on_mismatch)
        emit({"summary": (unchanged, left_out(entries, pairs, current, only=only, skip=skip), len(writes))})
        if plan_only:
            for w in writes:
                emit({"write": w})
            return
        done: list = []
        try:
            execute(bus, writes, done, allow=allow, on_write=lambda w: emit({"write": w}))
        finally:
            emit({"done": (done, writes)})

    for rec in buses.run(specs, work, open_bus=open_bus):
        for kind in ("write", "summary", "done"):
            if kind in rec:
                yield kind, rec["bus"], rec[kind]
