"""Check mode: run a command's own code up to its first effect, and no further.

A batch is checked whole before anything is sent: each line's command runs in check mode, so
every check the command makes at run time — option types and ranges, limits, IDs, conditions,
input files, output paths, permissions — runs exactly as it will at run time (the same code,
not a list of checks kept beside it). The command stops at its first effect with
:class:`Checked`; the effects are, by definition, what a command must not do before it has
checked everything:

- opening or borrowing a port (:func:`zkzap.link.port.open_port`, the batch's shared port),
- starting a telemetry bridge (it connects to a broker or a ground station),
- creating, truncating or replacing a file (:mod:`zkzap.outfile`, the logbook).

A consent asked on the way (the command line's ``--yes`` prompt) is recorded instead of asked
(:attr:`Check.consents`), so a batch can ask once for all its lines. Outside check mode
:func:`effect` does nothing.
"""

from __future__ import annotations

import contextlib

_active = None


class Checked(BaseException):
    """The checked command reached its first effect: everything before it passed.

    A BaseException, so that a command's own ``except Exception`` never takes it for a
    failure; ``what`` names the effect, ``facts`` its details (``ids`` of a mightyZAP port)."""

    def __init__(self, what, facts):
        super().__init__(what)
        self.what = what
        self.facts = facts


class Check:
    """What one checked command did before its first effect."""

    def __init__(self):
        self.consents = []
        """The consents it would have asked for (their one-line descriptions)."""
        self.effect = None
        """``(what, facts)`` of the effect it stopped at, or None when it ran to its end."""


def active():
    """The :class:`Check` in progress, or None (the command runs for real)."""
    return _active


def effect(what: str, **facts) -> None:
    """Called where a command is about to act (open a port, write a file, connect a bridge):
    in check mode the command stops here (:class:`Checked`); otherwise nothing happens."""
    if _active is not None:
        _active.effect = (what, facts)
        raise Checked(what, facts)


def consent(action: str) -> bool:
    """In check mode, record the consent ``action`` would need and return True (not asked);
    outside it, return False (ask as usual)."""
    if _active is None:
        return False
    if action not in _active.consents:
        _active.consents.append(action)
    return True


@contextlib.contextmanager
def checking():
    """``with checking() as check:`` runs the block in check mode; a :class:`Checked` raised
    inside ends the block normally (the command passed its checks)."""
    global _active
    outer, _active = _active, Check()
    check = _active
    try:
        yield check
    except Checked:
        pass
    finally:
        _active = outer
