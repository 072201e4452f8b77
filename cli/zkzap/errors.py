"""Exit codes and the errors that carry them. Stable: scripts branch on these numbers."""

from __future__ import annotations

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
#: Interrupted by Ctrl-C (SIGINT); 143 for SIGTERM.
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
    (INTERRUPTED, "interrupted (Ctrl-C); 143 when terminated (SIGTERM)"),
)


class ZkzapError(Exception):
    """The root of every zkzap error: a one-line message stating the facts, and an exit code.

    Keyword arguments become attributes and are kept in :attr:`facts` (for example ``ident``,
    ``baud``, ``timeout``, ``tries`` of a :class:`NoReply`), so a program can act on them
    without parsing the message. Only the command line adds hints on what to try next.
    """

    #: The exit status the command line exits with for this error.
    code = USAGE

    def __init__(self, message, code=None, **facts):
        super().__init__(message)
        if code is not None:
            self.code = code
        self.facts = facts
        for key, value in facts.items():
            setattr(self, key, value)

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

    def __init__(self, what, module, extra):
        super().__init__(f"{what}: needs the {module} library; install it with pip install 'zkzap[{extra}]'",
                         module=module, extra=extra)


class CheckFailed(ZkzapError):
    """A check failed: a CRC or checksum mismatch, a read-back that differs, a goal not reached."""

    code = CHECK_FAILED


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


class Interrupted(ZkzapError):
    """A session was stopped by SIGINT (exit 130) or SIGTERM (exit 143)."""

    code = INTERRUPTED


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


def exit_status_help(meanings=None, tail="") -> str:
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
        raise ValueError(f"exit codes {unknown} are not in the exit-code table")
    return "Exit status: " + "; ".join(f"{c} {meanings[c]}" for c in order if c in meanings) + "." + tail
