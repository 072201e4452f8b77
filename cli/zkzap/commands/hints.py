"""What to try next: the hints the command line adds to a library error's facts.

The library's errors state facts (ID, baud rate, timeout, tries; see :mod:`zkzap.errors`);
what a user of the command line should try next is this module's business, so the library
never names a command.
"""

from __future__ import annotations

from ..errors import CheckFailed, InvalidValue, NoReply, PermissionNeeded, PortError, UsageError


def hint(e) -> str:
    """The hint for ``e`` (with its leading separator), or ``""``."""
    facts = getattr(e, "facts", {})
    if isinstance(e, NoReply) and facts.get("protocol") == "zap" and facts.get("tries") is not None:
        if facts.get("late") or facts.get("late_before"):
            return "; replies arrive late (after the window): try a longer --timeout"
        text = "; check the ID, the baud rate ('zap scan --baud all'), power and wiring"
        if facts.get("mode_dependent"):
            text += "; or the actuator's feedback-return-mode does not answer this (try 'zap echo')"
        return text
    if isinstance(e, PermissionNeeded):
        return _permission_hint(e)
    if isinstance(e, InvalidValue) and facts.get("field") == "register" and not facts.get("suggestions"):
        return "; 'zap registers' lists them"
    if isinstance(e, NoReply) and facts.get("noise"):
        if facts.get("protocol") == "zap":
            return "; sniff at the bus's baud rate (-b); 'zap scan --baud all' finds the actuators' (it transmits)"
        return "; 'zk detect -p PORT' finds the ECU's baud rate and stop bits by listening"
    if isinstance(e, UsageError):
        if facts.get("assumed_mode"):
            return "; give --return-mode 1 or 2 if the actuator is set so"
        if facts.get("no_port") == "zap":
            return ": give -p PORT (or set ZKZAP_ZAP_PORT), --sim, or -n to print the packet"
    if isinstance(e, PortError) and facts.get("busy"):
        import os

        if facts.get("holders"):
            return "; stop it, or use another port"
        if os.name == "posix" and str(facts.get("url", "")).startswith("/"):
            return f"; 'fuser -v {facts['url']}' names it (as root for another user's programs)"
        return "; close the other program"
    if isinstance(e, CheckFailed):
        if facts.get("taken"):
            return "; choose a free ID ('zap scan') or pass --force"
        if facts.get("shared"):
            return "; connect one of them alone and give it a free ID ('zap set-id'), then run this again"
        if facts.get("duplicate"):
            return "; connect the one to change alone and check with 'zap scan'"
        if facts.get("after_change") == "id":
            return "; check with 'zap scan'"
        if facts.get("after_change") == "baud":
            return "; try 'zap scan --baud all'"
    return ""


def _permission_hint(e) -> str:
    """What the command line maps onto the missing permissions: --force, --yes."""
    from ..codec import zap
    from ..codec.permissions import CONSENT, FORCE, Permission

    parts = []
    frame = getattr(e, "frame", b"")
    if e.missing & Permission.IDENTITY and len(frame) > 6 and frame[5] in zap.WRITE_CODES:
        cmd = zap.Command(frame)
        if zap.REGISTER_BY_NAME["id"].address in [cmd.address] and not cmd.broadcast:
            parts.append("'zap set-id NEW --id OLD' checks that NEW is free and reads it back")
        elif zap.REGISTER_BY_NAME["baud-rate"].address in [cmd.address] and not cmd.broadcast:
            parts.append("'zap set-baud BAUD --id ID' restarts the actuator and verifies")
    flags = []
    if e.missing & FORCE:
        flags.append("--force")
    if e.missing & CONSENT:
        flags.append("--yes")
    if flags:
        parts.append(("or " if parts else "") + f"pass {' and '.join(flags)} to do it anyway"
                     if parts else f"pass {' and '.join(flags)} to do it")
    return "".join(f"; {p}" for p in parts)
def adapter_notes(bus) -> None:
    """Notes about a mightyZAP bus's USB adapter, on stderr: at once, when ``--low-latency``
    could not be had; when the command ends (once per process), how to lower an FTDI adapter's
    latency timer when the measured latency shows it."""
    import click

    from .options import note

    if bus.low_latency is False:
        note(f"--low-latency: {bus.url}: not available ({bus.low_latency_reason})")
    ctx = click.get_current_context(silent=True)
    if ctx is not None:
        ctx.call_on_close(lambda: _latency_timer_note(bus))


def _latency_timer_note(bus) -> None:
    policy = bus.policy
    effect = policy.adapter_effect()
    if effect is None or policy.hinted:
        return
    policy.hinted = True
    from ..link.adapters import latency_timer_hint
    from .options import note

    typical, timer, device = effect
    note(f"replies take {typical * 1000:.1f} ms, most of it in the USB adapter: "
         + latency_timer_hint(device, round(timer * 1000)))


def with_hint(e) -> str:
    """The error's message followed by its hint."""
    return str(e) + hint(e)
