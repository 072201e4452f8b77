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
    """An error with a one-line message and an exit code."""

    code = USAGE

    def __init__(self, message, code=None):
        super().__init__(message)
        if code is not None:
            self.code = code


class UsageError(ZkzapError):
    code = USAGE


class CheckFailed(ZkzapError):
    code = CHECK_FAILED


class NoReply(ZkzapError):
    code = NO_REPLY


class PortError(ZkzapError):
    code = PORT_ERROR


class DeviceError(ZkzapError):
    code = DEVICE_ERROR


class BadReply(ZkzapError):
    code = BAD_REPLY


class OutputError(ZkzapError):
    """The output could not be written (disk full, file system gone). The records written
    before the failure are whole."""

    code = OUTPUT_ERROR
