"""Exit codes and the errors that carry them. Stable: scripts branch on these numbers.

Every error zkzap raises for bad input or for what a device did is a :class:`ZkzapError`:

- :class:`UsageError` (exit 2): bad usage or input; nothing was sent.

  - :class:`InvalidValue` (also a ``ValueError``): a value outside its range or grid, an
    unknown name (with the closest names: :func:`did_you_mean`), malformed text. The codec's
    :class:`~zkzap.codec.fields.FieldValueError` and :class:`~zkzap.codec.hexfmt.HexError`
    are InvalidValue errors.
  - :class:`PermissionNeeded`: a frame needs a permission (:class:`~zkzap.codec.permissions.Permission`)
    its sender was not given; nothing was sent.

- :class:`CheckFailed` (1), :class:`NoReply` (3), :class:`PortError` (4),
  :class:`DeviceError` (5), :class:`BadReply` (6), :class:`OutputError` (7),
  :class:`MoreToDo` (8), :class:`Interrupted` (130/143).
- The codec's frame errors (:class:`~zkzap.codec.zk.FrameError`,
  :class:`~zkzap.codec.zap.PacketError`; exit 2) are ZkzapErrors and ValueErrors; their CRC
  and checksum mismatches (:class:`~zkzap.codec.zk.CrcError`,
  :class:`~zkzap.codec.zap.ChecksumError`) are also :class:`CheckFailed` (exit 1).
"""

from __future__ import annotations

TYPE_CHECKING = False
if TYPE_CHECKING:  # for the annotations only: typing costs start-up
    from typing import Any, Iterable, Mapping, Optional

    from .codec.permissions import Permission

OK = 0
#: A check failed: CRC/checksum mismatch (``crc --check``, an explicit bad frame), read-back mismatch.
CHECK_FAILED = 1
#: Bad usage or input: unknown option, value out of range, bad hex. Nothing was sent.
USAGE = 2
#: No reply: the device did not answer within the timeout (after retries).
NO_REPLY = 3
#: The port could not be opened, or failed/vanished while in use.
PORT_ERROR = 4
#: The device answered with an error (mightyZAP error bits, an ECU error code where asked to fail).
DEVICE_ERROR = 5
#: The reply was malformed or corrupted (bad checksum, wrong ID) after every retry.
BAD_REPLY = 6
#: The output could not be written (disk full, file system gone); records before it are whole.
OUTPUT_ERROR = 7
#: More to do: the command did the part it was asked to and stopped; running it again goes on
#: (``zap setup --no-wait`` set up one actuator and others are pending).
MORE_TO_DO = 8
#: Interrupted by Ctrl-C (SIGINT); 143 for SIGTERM, 128 + N for another signal N.
INTERRUPTED = 130
TERMINATED = 143

EXIT_CODES = (
    (OK, "success"),
    (CHECK_FAILED, "check failed: CRC/checksum mismatch, read-back differs"),
    (USAGE, "usage error or bad input (value out of range, unknown name, bad hex); nothing sent"),
    (NO_REPLY, "no reply from the device within the timeout"),
    (PORT_ERROR, "port cannot be opened, or failed or vanished while in use"),
    (DEVICE_ERROR, "the device reported an error (actuator error bits, ECU error code)"),
    (BAD_REPLY, "corrupted or unexpected reply (bad checksum, wrong ID) after retries"),
    (OUTPUT_ERROR, "the output could not be written (disk full); the records before are whole"),
    (MORE_TO_DO, "more to do: the part asked for is done and the command stopped; run it again for the rest"),
    (INTERRUPTED, "interrupted (Ctrl-C); 143 when terminated (SIGTERM), 128+N by another signal N (129 SIGHUP)"),
)


class ZkzapError(Exception):
    """The root of every zkzap error: a one-line message stating the facts, and an exit code.

    Keyword arguments become attributes and are kept in :attr:`facts` (for example ``ident``,
    ``baud``, ``timeout``, ``tries`` of a :class:`NoReply`), so a program can act on them
    without parsing the message. Only the command line adds hints on what to try next.
    """

    #: The exit status the command line exits with for this error.
    code: int = USAGE
    #: The facts given as keyword arguments (each also an attribute).
    facts: dict[str, Any]

    def __init__(self, message: object, code: Optional[int] = None, **facts: Any) -> None:
        super().__init__(message)
        if code is not None:
            self.code = code
        self.facts = facts
        for key, value in facts.items():
            setattr(self, key, value)

    if TYPE_CHECKING:  # the facts are attributes too (which ones depends on where it was raised)
        def __getattr__(self, name: str) -> Any: ...

    @property
    def message(self) -> str:
        """The message (facts only, no hint)."""
        return str(self)


class UsageError(ZkzapError):
    """Bad usage or input (a value out of range, an unknown name): nothing was sent."""

    code = USAGE


class MissingExtra(UsageError):
    """An optional library that ``what`` needs is not installed: the message names the extra
    that provides it (``pip install 'zkzap[mqtt]'``)."""

    def __init__(self, what: str, module: str, extra: str) -> None:
        super().__init__(f"{what}: needs the {module} library; install it with pip install 'zkzap[{extra}]'",
                         module=module, extra=extra)


class InvalidValue(UsageError, ValueError):
    """A value outside what is allowed (a range, a grid, a set of names) or malformed text; the
    message names the field and what is allowed. Also a ``ValueError``. An unknown name carries
    ``suggestions``, the closest allowed names (:func:`did_you_mean`)."""


class PermissionNeeded(UsageError):
    """A frame needs a permission it was not given: nothing was sent (exit 2).

    Facts: ``missing`` and ``needed`` (:class:`zkzap.codec.permissions.Permission` flags),
    ``reasons`` ({Permission: why}, the missing ones), ``frame`` (the bytes not sent) and
    ``simulated`` (whether the port was a simulator, which grants the consent permissions)."""

    missing: Permission
    needed: Permission
    reasons: dict[Permission, str]
    frame: bytes
    simulated: bool


class CheckFailed(ZkzapError):
    """A check failed: a CRC or checksum mismatch, a read-back that differs, a goal not reached."""

    code = CHECK_FAILED


class GoalClamped(UserWarning):
    """A warning (:mod:`warnings`), not an error: an actuator clamped the goal position it was
    sent to its stroke limits, so the move ends elsewhere than asked. ``ident``, ``requested``
    (the goal sent) and ``goal`` (the one the actuator holds) are attributes; the move's result
    (:class:`zkzap.api.zap.Moved`) says the same. ``warnings.simplefilter("error", GoalClamped)``
    makes it an exception."""

    def __init__(self, message: str, *, ident: int, requested: int, goal: int) -> None:
        super().__init__(message)
        self.ident, self.requested, self.goal = ident, requested, goal


class IdTaken(CheckFailed):
    """The ID asked for answers already (another actuator has it): refused before anything was
    written, so a refusal (exit 2) rather than a failed check; still a :class:`CheckFailed`."""

    code = USAGE


class NoReply(ZkzapError):
    """The device did not answer within the timeout, after every try."""

    code = NO_REPLY


class PortError(ZkzapError):
    """The port could not be opened, or failed or vanished while in use."""

    code = PORT_ERROR


class DeviceError(ZkzapError):
    """The device reported an error (actuator error bits, an ECU error code)."""

    code = DEVICE_ERROR


class BadReply(ZkzapError):
    """The reply was malformed or corrupted (bad checksum, wrong ID) after every retry."""

    code = BAD_REPLY


class OutputError(ZkzapError):
    """The output could not be written (disk full, file system gone). The records written
    before the failure are whole."""

    code = OUTPUT_ERROR


class MoreToDo(ZkzapError):
    """The command did what it was asked to and stopped with more to do (exit 8): running it
    again goes on. Facts: ``pending`` (what is left)."""

    pending: list[int]

    code = MORE_TO_DO


class Interrupted(ZkzapError):
    """A session was stopped by SIGINT (exit 130) or SIGTERM (exit 143)."""

    code = INTERRUPTED


def clip(text: object, width: int = 40) -> str:
    """``text`` (its ``str``) cut to ``width`` characters with ``...``: what a message quotes of
    an input, which may be a 20 MiB cell."""
    text = str(text)
    return text if len(text) <= width else text[:width - 3] + "..."


def close_names(word: object, choices: Iterable[object], *, n: int = 3) -> list[str]:
    """The names of ``choices`` closest to ``word``, best first (at most ``n``; none when nothing
    is close). Case, ``-``/``_`` and surrounding blanks do not count; a name that contains the
    word (``voltage`` -> ``present-voltage``) counts as close, in the order of ``choices``, those
    that start like it first; otherwise
    :mod:`difflib` ranks the names by similarity and only the nearly best count. The one "did you mean" of zkzap: register and field
    names in files and on the command line, option choices, API names and keyword arguments."""
    names = [str(c) for c in choices]
    key = _fold(word)
    if not key or not names:
        return []
    folded = {}
    for name in names:
        folded.setdefault(_fold(name), name)
    if key in folded:
        return [folded[key]]
    import difflib

    contains = [name for f, name in folded.items() if len(key) >= 3 and key in f]
    if contains:         # in the order given (a table's), those that start like the word first
        return sorted(contains, key=lambda name: not _fold(name).startswith(key))[:n]
    # a ratio is at most 2*min/(sum) of the lengths: names that cannot reach 0.6 are not compared
    # (a 200 000-character key in a damaged file would take seconds of difflib for nothing)
    within = [f for f in folded if 2 * min(len(key), len(f)) >= 0.6 * (len(key) + len(f))]
    scored = sorted(((difflib.SequenceMatcher(None, key, f).ratio(), f) for f in within), reverse=True)
    best = scored[0][0] if scored else 0.0
    return [folded[f] for ratio, f in scored[:n] if ratio >= max(0.6, best - 0.1)]


def did_you_mean(word: object, choices: Iterable[object], *, otherwise: str = "", n: int = 3) -> str:
    """``"; did you mean speed-limit?"`` (or ``"; did you mean a, b or c?"``) for the names of
    ``choices`` closest to ``word`` (:func:`close_names`); ``otherwise`` when none is close."""
    close = close_names(word, choices, n=n)
    if not close:
        return otherwise
    listed = close[0] if len(close) == 1 else f"{', '.join(close[:-1])} or {close[-1]}"
    return f"; did you mean {listed}?"


def unknown_name(what: str, word: object, choices: Iterable[object], *, noun: str = "name",
                 otherwise: Optional[str] = None, cls: type = InvalidValue, **facts: Any) -> InvalidValue:
    """The :class:`InvalidValue` for an unknown name: ``"WHAT: unknown NOUN 'x'; did you mean
    y?"``,
    with ``name``, ``suggestions`` and ``facts`` as attributes (raise it). When no name is
    close the message ends with ``otherwise`` (default: ``"; allowed a, b, c"`` when there are
    at most 16 choices). ``cls``: a subclass of InvalidValue to raise instead."""
    choices = [str(c) for c in choices]
    if otherwise is None:
        otherwise = f"; allowed {', '.join(choices)}" if len(choices) <= 16 else ""
    hint = did_you_mean(word, choices, otherwise=otherwise)
    error: InvalidValue = cls(f"{what}: unknown {noun} {clip(repr(str(word)), 60)}{hint}", name=word,
                              suggestions=close_names(word, choices), **facts)
    return error


def _fold(text: object) -> str:
    return str(text).strip().lower().replace("_", "-")


def exit_code(exc: BaseException) -> int:
    """The exit status that goes with ``exc``: its code for a :class:`ZkzapError`, 130 for
    KeyboardInterrupt, 2 for a codec value error, else 1."""
    if isinstance(exc, ZkzapError):
        return exc.code
    if isinstance(exc, KeyboardInterrupt):
        return INTERRUPTED
    if isinstance(exc, ValueError):
        return USAGE
    return CHECK_FAILED


def exit_status_help(meanings: Optional[Mapping[int, str]] = None, tail: str = "") -> str:
    """'Exit status: 0 success; 1 ...' from :data:`EXIT_CODES` (for help texts).

    ``meanings`` maps the codes a command can exit with to what they mean for it (a command's
    own wording), listed in the table's order (143 after 130); a code that is not in the table
    raises ValueError. ``tail`` follows the list."""
    if meanings is None:
        return "Exit status: " + "; ".join(f"{c} {t}" for c, t in EXIT_CODES) + "." + tail
    order = [c for c, _ in EXIT_CODES]
    order.insert(order.index(INTERRUPTED) + 1, TERMINATED)
    unknown = sorted(set(meanings) - set(order))
    if unknown:
        raise InvalidValue(f"exit codes {unknown} are not in the exit-code table")
    return "Exit status: " + "; ".join(f"{c} {meanings[c]}" for c in order if c in meanings) + "." + tail
