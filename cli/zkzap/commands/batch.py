"""``zap batch`` and ``zk batch``: many commands over one open port, one JSON Lines record each.

A batch file has one command per line in the command line's own grammar, without the program
name and the port options (``load present-position --id 1``; ``# comments`` and blank lines
are skipped). Every line is checked whole before anything is sent: its command runs in check mode
(:mod:`zkzap.checking`), every check it makes at run time, up to its first effect (a port, a
file, a bridge); a bad line is refused naming ``FILE:LINE`` (exit 2).
One consent (``--yes``, or one prompt on a terminal) covers every stored write and every
engine-starting command of the batch. Then the lines run in order over the one port (see
:mod:`zkzap.link.shared`); each gives a record ``{"line", "command", "exit", "result"}`` (and
``"error"``, the message, when it failed): ``result`` is what the command printed, parsed as
JSON where it is JSON (a bare value, a record, or a list of records), else its text.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shlex
import signal
import sys
import threading

import click

from .. import signals
from ..errors import INTERRUPTED, MORE_TO_DO, OK, OUTPUT_ERROR, USAGE, UsageError, ZkzapError
from . import PipeClosed
from .options import exits, note

#: Options a batch line may not carry: the port is the batch's.
PORT_TOKENS = ("-p", "--port", "--sim", "--sim-ids", "-b", "--baud", "--stop-bits", "--capture", "--low-latency")
#: Port options a command takes as its own argument: the baud rates a scan tries.
OWN_TOKENS = {"scan": ("-b", "--baud")}


def port_tokens(tokens) -> list:
    """The port options among a line's tokens (which a line may not give)."""
    own = OWN_TOKENS.get(tokens[0], ()) if tokens else ()
    return [t.split("=", 1)[0] for t in tokens if t.split("=", 1)[0] in PORT_TOKENS
            and t.split("=", 1)[0] not in own]


#: A line's record as JSON (one encoder for every line).
_encode = json.JSONEncoder(ensure_ascii=False).encode

#: Commands a batch line cannot run.
EXCLUDED = {"zap": {"batch", "decode"}, "zk": {"batch", "decode"}}

#: The zk batch's and shell's own lines: the stand's alarm list (its sessions share one) and its
#: acknowledgement. ``ack [ID ...] [--by NAME]``; ``alarms``.
STAND_BUILTINS = {"zk": ("alarms", "ack")}


def parse_builtin(tokens) -> dict:
    """The arguments of a stand line (``alarms``; ``ack [ID ...] [--by NAME]``); UsageError for
    anything else."""
    name, args = tokens[0], list(tokens[1:])
    if name == "alarms":
        if args:
            raise UsageError("alarms: takes no argument")
        return {"op": "alarms"}
    ids, by = [], None
    while args:
        a = args.pop(0)
        if a == "--by" or a.startswith("--by="):
            value = a[5:] if a.startswith("--by=") else (args.pop(0) if args else None)
            if value is None or not value.strip():
                raise UsageError("ack: --by needs the operator's name (--by NAME)")
            by = value.strip()
        elif a.isascii() and a.isdigit() and 0 < int(a) < 10 ** 9:
            ids.append(int(a))
        else:
            raise UsageError(f"ack: {a!r} is no alarm number; 'ack' acknowledges every latched alarm, "
                             f"'ack N ...' those numbered (see 'alarms'), --by NAME says who")
    return {"op": "ack", "ids": ids or None, "by": by}


def operator(where=None) -> str:
    """Who acknowledges: the user's name (and where the line is: ``alice (zk batch run.txt:4)``)."""
    import getpass

    try:
        who = getpass.getuser()
    except Exception:  # noqa: BLE001 - no user name in this environment
        who = "the user"
    return f"{who} ({where})" if where else who


def run_builtin(parsed, who) -> tuple:
    """Run a stand line on the process's alarm list (:func:`zkzap.api.alarms.current`): returns
    ``(exit status, result)``; ``ack``'s result lists the alarms acknowledged (who and when),
    ``alarms``'s the list and whether a start is allowed (``start``: null, or the refusal)."""
    from ..api.alarms import current

    alarms = current()
    if parsed["op"] == "ack":
        ids = parsed["ids"]
        if ids is not None:
            known = {a.id for a in alarms.entries}
            unknown = [i for i in ids if i not in known]
            if unknown:
                from . import _error

                _error(f"ack: no alarm {', '.join(map(str, unknown))} in the list (its numbers: "
                       f"{', '.join(str(a.id) for a in alarms.entries) or 'none, it is empty'})", "zk")
                return USAGE, None
        done = alarms.acknowledge(parsed["by"] or who, ids)
        if not done:
            note("ack: no alarm is latched")
        return OK, [{k: a.to_dict()[k] for k in ("id", "kind", "text", "acked_by", "acked_at")} for a in done]
    return OK, {"alarms": alarms.to_list(), "start": alarms.refusal()}


class Line:
    """One command of a batch: where it is, its text, its tokens and its command path."""

    __slots__ = ("where", "number", "text", "tokens", "path", "params", "consents", "effect", "leaf", "checked",
                 "builtin")

    def __init__(self, where, number, text, tokens):
        self.where, self.number, self.text, self.tokens = where, number, text, tokens
        self.path = []
        self.params = {}
        self.consents = []      # what the line's command would ask consent for (see check_lines)
        self.effect = None      # (what, facts) of the first effect its check stopped at
        self.leaf = None
        self.checked = False    # its command ran in check mode (its files' checks included)
        self.builtin = None     # a stand line's arguments (see STAND_BUILTINS)


#: The longest batch line (characters): a real one is a command and its options, and the
#: shell-like splitting takes time that grows with the square of a line's length.
MAX_LINE = 16384


def read_lines(source, name):
    """``[Line]`` of a batch text (comments and blank lines skipped); a line that does not split,
    or is longer than :data:`MAX_LINE`, is refused naming ``NAME:LINE``."""
    out = []
    split = {}                     # text -> (tokens, quoted): a batch repeats its lines (a poll)
    for number, raw in enumerate(source, 1):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        where = f"{name}:{number}"
        if len(text) > MAX_LINE:
            raise UsageError(f"{where}: a line of {len(text)} characters; a batch line has at most {MAX_LINE}")
        known = split.get(text)
        if known is None:
            try:
                tokens = shlex.split(text, comments=True)
            except ValueError as e:
                raise UsageError(f"{where}: {e}") from None
            known = split[text] = (tokens, " ".join(shlex.quote(t) for t in tokens))
        if not known[0]:
            continue
        out.append(Line(where, number, known[1], list(known[0])))
    return out


def _resolve(group, line, protocol):
    """The command path of a line (``["send", "control"]``) and the leaf command."""
    ctx = click.Context(group, info_name=protocol)
    cmd = group
    args = list(line.tokens)
    path = []
    while isinstance(cmd, click.Group):
        if not args:
            raise UsageError(f"{line.where}: {' '.join([protocol] + path)}: a sub-command is missing")
        name = args.pop(0)
        if not path and name in EXCLUDED[protocol]:
            raise UsageError(f"{line.where}: {name}: not in a batch")
        sub = cmd.get_command(ctx, name)
        if sub is None:
            names = ", ".join(n for n in cmd.list_commands(ctx) if n not in EXCLUDED[protocol] or path)
            raise UsageError(f"{line.where}: unknown command {name!r}; allowed {names}")
        path.append(name)
        ctx = click.Context(sub, info_name=name, parent=ctx)
        cmd = sub
    return path, cmd, args, ctx.parent


def _refuse(line, e):
    if isinstance(e, click.ClickException):
        text = " ".join(e.format_message().split())
    else:
        text = str(e)
    raise UsageError(f"{line.where}: {' '.join(line.path)}: {text}") from None


def _batch_capture():
    """The lines of a batch leave the batch's ``--capture`` be (they have none of their own)."""
    if "zkzap.link.capture" not in sys.modules:
        return contextlib.nullcontext()     # no capture asked for: import nothing
    from ..link import capture

    return capture.keep()


def check_lines(group, lines, protocol, defaults):
    """Check every line whole before anything is sent: parse it as its command would (types,
    ranges), then run the command itself in check mode (:mod:`zkzap.checking`) up to its first
    effect, so every check it makes at run time runs now — limits, IDs, conditions, input files,
    output paths, permissions — and the consents it would ask for are recorded on the line. A
    bad line raises UsageError naming ``FILE:LINE``."""
    with _batch_capture():
        _check_lines(group, lines, protocol, defaults)


def _paths(leaf, params, kind):
    """The file names ``params`` give the parameters of ``leaf`` whose type is ``kind``
    (InputPath or OutputPath), as absolute paths."""
    out = []
    for p in leaf.params:
        if isinstance(p.type, kind):
            value = params.get(p.name)
            for v in (value if isinstance(value, (list, tuple)) else (value,)):
                if isinstance(v, str) and v not in ("", "-"):
                    out.append(os.path.abspath(v))
    return out


def _check_lines(group, lines, protocol, defaults):
    from .options import InputPath, OutputPath

    seen = {}
    made = set()                           # the files earlier lines write
    for line in lines:
        twin = seen.get(tuple(line.tokens))
        if twin is not None:               # the same text checks the same: reuse the first's findings
            line.path, line.params, line.leaf = twin.path, twin.params, twin.leaf
            line.consents, line.effect, line.checked = twin.consents, twin.effect, twin.checked
            line.builtin = twin.builtin
            continue
        seen[tuple(line.tokens)] = line
        if line.tokens[0] in STAND_BUILTINS.get(protocol, ()):
            try:
                line.builtin = parse_builtin(line.tokens)
            except UsageError as e:
                raise UsageError(f"{line.where}: {e}") from None
            line.path, line.checked = [line.tokens[0]], True
            continue
        bad = port_tokens(line.tokens)
        if bad:
            raise UsageError(f"{line.where}: {bad[0]}: the port is the batch's; give it to "
                             f"'{protocol} batch', not to a line")
        line.path, leaf, args, parent = _resolve(group, line, protocol)
        line.leaf = (leaf, parent)
        try:
            with leaf.make_context(line.path[-1], list(args), parent=parent,
                                   default_map=defaults) as ctx:
                line.params = dict(ctx.params)
        except Exception as e:  # noqa: BLE001 - click's, the codec's and zkzap's: all name the problem
            _refuse(line, e)
        # a line that reads what an earlier line writes (a backup, then its apply) is parsed
        # whole now and runs its file's checks when it runs, after the line that makes the file
        if not any(f in made and not os.path.exists(f) for f in _paths(leaf, line.params, InputPath)):
            _check_run(line, protocol)
        made.update(_paths(leaf, line.params, OutputPath))


def _check_run(line, protocol):
    """Run the line's command in check mode: up to its first effect, its output discarded."""
    from .. import checking

    out, err = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), checking.checking() as check:
        code = invoke(line, protocol)
    line.consents, line.effect = check.consents, check.effect
    line.checked = code != USAGE
    if code == USAGE:
        message = err.getvalue().strip().splitlines()
        text = message[-1].split("error: ", 1)[-1] if message else f"exit status {code}"
        raise UsageError(f"{line.where}: {' '.join(line.path)}: {text}")


def consent_items(lines):
    """``["FILE:LINE store id 7 --id 1 (id)", ...]``: the lines that need a consent on a real
    port, with what each would have asked for (recorded while checking)."""
    return [f"{line.where} {line.text} ({'; '.join(line.consents)})" for line in lines if line.consents]


def line_ids(line) -> list:
    """The actuator IDs a checked zap line addresses (its --id, and the IDs it opened the bus for)."""
    ids = []
    ident = line.params.get("ident")
    if isinstance(ident, int):
        ids.append(ident)
    if line.effect is not None:
        ids += line.effect[1].get("ids") or []
    return ids


def parse_result(text):
    """What a command printed: None, a JSON value (a bare value, a record, a JSON array), a
    list of JSON Lines values, or the text itself."""
    if not text.strip():
        return None
    digits = text[:-1]
    if text[-1] == "\n" and digits.isascii() and digits.isdigit() and (digits[0] != "0" or len(digits) == 1):
        return int(digits)                 # a bare value, the commonest result (what JSON reads it as)
    try:
        return json.loads(text)
    except ValueError:
        pass
    values = []
    for r in text.splitlines():
        if not r.strip():
            continue
        try:
            values.append(json.loads(r))
        except ValueError:
            return text.rstrip("\n")
    return values


#: How many lines' click contexts a batch keeps for reuse (a batch repeats its lines: a poll).
CONTEXTS = 16


def _context(line, contexts):
    """A click context for running ``line``'s command: the one ``contexts`` keeps for its text
    (click makes a context ready for reuse when it closes), else a new one, kept."""
    key = id(line.leaf)                    # twins share their first's leaf (see _check_lines)
    held = contexts.get(key)
    if held is None or held[0] is not line.leaf:
        if len(contexts) >= CONTEXTS:
            contexts.clear()
        leaf, parent = line.leaf
        held = contexts[key] = (line.leaf, click.Context(leaf, info_name=line.path[-1], parent=parent))
    return held[1]


def invoke(line, protocol, contexts=None) -> int:
    """Run a checked line's command with the parameters its check parsed (the same defaults,
    so the same values as parsing it again), with the command line's error conventions.
    Returns its exit status. ``contexts``: where a run keeps its lines' click contexts."""
    leaf = line.leaf[0]
    prog = protocol
    try:
        ctx = _context(line, {} if contexts is None else contexts)
        ctx.params = dict(line.params)
        with ctx:
            if line.checked:               # its check ran its files' checks on these very parameters
                leaf.callback(**ctx.params)
            else:
                leaf.invoke(ctx)
        return 0
    except click.exceptions.Exit as e:
        return e.exit_code
    except click.ClickException as e:
        from . import _error

        _error(" ".join(e.format_message().split()), prog)
        return e.exit_code
    except click.exceptions.Abort:
        return INTERRUPTED
    except KeyboardInterrupt as e:         # Ctrl-C, or Terminated (SIGTERM, ...): 130, 143, 128 + N
        return signals.exit_status(e)
    except (BrokenPipeError, PipeClosed):
        raise
    except ZkzapError as e:
        from . import _error
        from .hints import with_hint

        _error(with_hint(e), prog)
        return e.code


#: The exit statuses of 'zap batch' and 'zk batch': a failed line's, the first one's.
_BATCH_MEANINGS = {OK: "every line succeeded", USAGE: "a bad line (FILE:LINE) or usage: nothing was sent"}
_BATCH_TAIL = " Any other status is the first failed line's (its record says it too)."
BATCH_EXITS = exits(_BATCH_MEANINGS, tail=_BATCH_TAIL)
#: A mightyZAP batch: a 'setup --no-wait' line that stops with IDs pending is "more to do" (8).
ZAP_BATCH_EXITS = exits({**_BATCH_MEANINGS,
                         MORE_TO_DO: "a setup line stopped as asked with IDs pending (run the batch again)"},
                        tail=_BATCH_TAIL)


def run_lines(group, protocol, lines, defaults, out, *, keep_going=False, keep_baud_after=()):
    """Run checked lines in order (the port already shared); write one record per line to
    ``out``. Returns the batch's exit status: 0, or the first failure's code.

    The first SIGINT/SIGTERM (or any signal that ends a program) stops the running line after its current transaction
    (:mod:`zkzap.link.stop`): the line ends as the command does on Ctrl-C, its record says exit
    130 (143 for SIGTERM, 128 + N for another signal N) with what it gathered, and no further line starts. A second signal
    interrupts at once."""
    with _batch_capture():
        return _run_lines(group, protocol, lines, defaults, out, keep_going=keep_going,
                          keep_baud_after=keep_baud_after)


def _error_of(messages):
    """The last error message a line said (None: none)."""
    errors = [m.split("error: ", 1)[1] for m in messages.splitlines() if "error: " in m]
    return errors[-1] if errors else None


#: A line's output is kept (and its record written whole, its result parsed as a whole) up to this
#: many characters; beyond, the record is streamed: written as the output comes, its result the
#: list of the output's lines, each its JSON value or, where it is none, its text.
STREAM_AFTER = 1 << 16
#: A streamed record's values are handed to its output this many characters at a time.
STREAM_CHUNK = 1 << 14


def _json_item(text):
    """One line of a streamed result as JSON: the line itself where it is a JSON value, else
    the line as a string."""
    text = text.strip()
    try:
        json.loads(text, parse_constant=_no_constant)
    except ValueError:
        return _encode(text)
    return text


def _no_constant(name):
    raise ValueError(f"{name} is no JSON value")


class _LineOutput(io.StringIO):
    """What a batch line prints (its stdout): kept up to :data:`STREAM_AFTER` characters, then
    streamed into its record (:meth:`_Records.begin`), so that memory stays bounded whatever a
    line prints (a long ``monitor``, a ``send --for`` of hours). A write may come from another
    thread (an output's lane)."""

    def __init__(self, records, limit=None):
        super().__init__()
        self._records = records
        self._limit = STREAM_AFTER if limit is None else limit
        self._lock = threading.Lock()
        self.line = None
        self._reset()

    def _reset(self):
        self.streamed = False
        self._size = 0
        self._tail = ""
        self._first = True
        self._pending, self._held = [], 0

    def start(self, line) -> None:
        """A new line runs: its output starts empty."""
        self.seek(0)
        self.truncate()
        self.line = line
        self._reset()

    def write(self, text):
        with self._lock:
            if not self.streamed:
                n = super().write(text)
                self._size += len(text)
                if self._size > self._limit:
                    kept = self.getvalue()
                    self.seek(0)
                    self.truncate()
                    self.streamed = True
                    self._records.begin(self.line)
                    self._stream(kept)
                return n
            self._stream(text)
            return len(text)

    def _stream(self, text):
        parts = (self._tail + text).split("\n")
        self._tail = parts.pop()
        for p in parts:
            if p.strip():
                value = _json_item(p)
                self._pending.append(value)
                self._held += len(value)
        if self._held >= STREAM_CHUNK:
            self._hand_over()

    def _hand_over(self):
        """The values gathered go to the records' output (in chunks: one hand-over per record
        would cost a thread switch each)."""
        if self._pending:
            self._records.items(self._pending, self._first)
            self._first = False
            self._pending, self._held = [], 0

    def finish(self, code, messages):
        """The line ended: ``(True, None)`` when its record was streamed (now ended), else
        ``(False, what it printed)``."""
        with self._lock:
            if not self.streamed:
                return False, self.getvalue()
            if self._tail.strip():
                self._pending.append(_json_item(self._tail))
            self._tail = ""
            self._hand_over()
            self._records.end(code, messages)
            return True, None


class _LineMessages(io.StringIO):
    """What a batch line says (its stderr): each message goes to the batch's stderr as soon as it
    is whole, after the records before it and prefixed with the line's ``FILE:LINE``, so that a
    long line's notes are neither held back nor kept; only the last error message is kept (its
    record's ``error``)."""

    def __init__(self, records, stderr):
        super().__init__()
        self._records = records
        self._stderr = stderr
        self._lock = threading.Lock()
        self.line = None
        self._tail = ""
        self.error = None
        self.said = False

    def start(self, line) -> None:
        self.line, self._tail, self.error, self.said = line, "", None, False

    def write(self, text):
        with self._lock:
            parts = (self._tail + text).split("\n")
            self._tail = parts.pop()
            if parts:
                self._say(parts)
            return len(text)

    def _say(self, messages):
        if not self.said:
            self.said = True
            try:
                self._records.flush()      # the records before, then this line's messages
                self._records.lane.drain()
            except Exception as e:  # noqa: BLE001 - the records' output failed: raised by the batch's next flush
                self._records.failed = self._records.failed or e
        for m in messages:
            if "error: " in m:
                self.error = m.split("error: ", 1)[1]
        self._stderr.write("".join(f"{self.line.where}: {m}\n" for m in messages))
        self._stderr.flush()

    def finish(self) -> str:
        """The line ended: its last words said; returns its last error message as a message
        (``error: ...``) for its record, or ''."""
        with self._lock:
            if self._tail:
                tail, self._tail = self._tail, ""
                self._say([tail])
        return f"error: {self.error}" if self.error is not None else ""


class _Records:
    """The batch's records on ``out``, in order. A line's record is written in the bus's next
    spare moment (:meth:`zkzap.link.zap_bus.ZapBus.spare`: the next line's request is on the
    wire, its reply on its way), so writing it never holds up the next transaction; it is
    written at once before anything else the batch says, and when the batch ends. A link
    without spare time (the ECU's) has each record written at once."""

    def __init__(self, out, link):
        from ..offload import Lane

        self.out = out
        # written off the bus's and the engine's path: a stdout nobody reads never holds a line up
        self.lane = Lane("stdout" if out is sys.stdout else getattr(out, "name", "the records"))
        self.spare = getattr(link, "spare", None)
        self.held = None               # (line, exit, printed, messages) not written yet
        self.queued = False            # the bus holds a call of _write (at most one)
        self.failed = None             # what writing raised in the bus's spare time

    def begin(self, line) -> None:
        """A line's output outgrew :data:`STREAM_AFTER`: its record is written as it comes (the
        records before it first), from its head: ``{"line": N, "command": "...", "result": [``."""
        self.flush()
        head = _encode({"line": line.number, "command": line.text})
        self.lane.call(self._emit, head[:-1] + ', "result": [')

    def items(self, values, first) -> None:
        """Values of a streamed record's result (JSON texts), after those written."""
        self.lane.call(self._emit, ("" if first else ", ") + ", ".join(values))

    def end(self, code, messages) -> None:
        """The end of a streamed record: its exit status (and error)."""
        tail = {"exit": code}
        if code:
            tail["error"] = _error_of(messages)
        self.lane.call(self._emit, "], " + _encode(tail)[1:] + "\n")

    def put(self, line, code, printed, messages) -> None:
        self.flush()
        self.held = (line, code, printed, messages)
        if self.spare is None:
            self.flush()
        elif not self.queued:
            self.queued = True
            self.spare(self._spared)

    def _spared(self) -> None:
        self.queued = False
        try:
            self._write()
        except Exception as e:  # noqa: BLE001 - a full disk, a closed pipe: raised by flush(), not in the bus
            self.failed = e

    def _write(self) -> None:
        if self.held is None:
            return
        line, code, printed, messages = self.held
        self.held = None
        rec = {"line": line.number, "command": line.text, "exit": code, "result": parse_result(printed)}
        if code:
            rec["error"] = _error_of(messages)
        self.lane.call(self._emit, _encode(rec) + "\n")

    def _emit(self, text) -> None:
        self.out.write(text)
        self.out.flush()

    def flush(self) -> None:
        """Write the held record now; raise what writing an earlier one raised."""
        failed, self.failed = self.failed, None
        if failed is not None:
            raise failed
        self.lane.check()
        self._write()

    def close(self) -> bool:
        """Write what is left (at most :data:`zkzap.offload.DRAIN_S`); False: the output is
        stalled (said on stderr; the writes left are not made)."""
        if self.lane.finish():
            self.lane.check()
            return True
        note(self.lane.lost())
        return False


def _run_lines(group, protocol, lines, defaults, out, *, keep_going=False, keep_baud_after=()):
    from ..link import stop
    from ..link.shared import Borrowed, shared

    first = 0
    last = None
    records = _Records(out, shared(protocol))
    # what a line prints, emptied for the next line (its output streamed when it grows large)
    buf, err = _LineOutput(records), _LineMessages(records, sys.stderr)
    contexts = {}
    with stop.deferring():
        try:
            for line in lines:
                if stop.requested() is not None:
                    break                          # between two lines: the next one does not start
                last = line
                Borrowed.keep_baud = line.path[0] in keep_baud_after
                saved = sys.stdout, sys.stderr
                buf.start(line)
                err.start(line)
                sys.stdout, sys.stderr = buf, err
                try:
                    if line.builtin is not None:
                        code, result = run_builtin(line.builtin, operator(f"{protocol} batch {line.where}"))
                        if result is not None:
                            buf.write(_encode(result) + "\n")
                    else:
                        code = invoke(line, protocol, contexts)
                finally:
                    sys.stdout, sys.stderr = saved
                    Borrowed.keep_baud = False
                messages = err.finish()            # said as they came; the last error kept
                signum = stop.requested()
                if signum is not None and stop.pending() is None and not code:
                    code = signals.status(signum)   # stopped, though the command returned
                streamed, printed = buf.finish(code, messages)
                if not streamed:
                    records.put(line, code, printed, messages)
                if code and not first:
                    first = code
                if code == INTERRUPTED or signals.terminated_status(code) or (code and not keep_going):
                    break
        finally:
            try:
                records.flush()
            finally:
                if not records.close() and not first:
                    first = OUTPUT_ERROR
        signum = stop.requested()
    if signum is not None:
        where = f"the current transaction of {last.where} ({last.text})" if last else "its start"
        note(f"{'interrupted' if signum == signal.SIGINT else 'terminated'}: the batch stopped after {where}")
        return signals.status(signum)
    return first


def read_source(path):
    """(lines of text, the name for messages) of FILE or '-' (stdin)."""
    from ..api.textfile import read_text

    text, name = read_text("-" if path is None else path, "batch", "one command per line")
    return text.splitlines(), name


def batch_exit(code):
    """End the batch command with ``code`` (0: return normally)."""
    if code:
        raise click.exceptions.Exit(code)


__all__ = ["read_lines", "check_lines", "run_lines", "consent_items", "line_ids", "USAGE"]
