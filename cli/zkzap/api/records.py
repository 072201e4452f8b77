"""The records the mightyZAP API returns, typed: each is a plain ``dict`` at run time (the keys
are the JSON keys the command line writes), and a :class:`~typing.TypedDict` to type checkers,
so ``rec["modle"]`` is an error before the program runs and ``rec["model"]`` is known to be an
``Optional[int]``.

- :class:`ScanRecord`: one actuator a scan found (:meth:`zkzap.Bus.scan`);
- :class:`Identity`: what :meth:`zkzap.Bus.identify` reads of one actuator;
- :class:`RegisterRow`: one register of :meth:`zkzap.Bus.dump` (and ``Actuator.dump()``);
- :class:`RegisterValue`: one register read, as :func:`zkzap.api.zap.register_records` gives it;
- :class:`Latency`: what a bus learned of one actuator's reply time (:attr:`zkzap.Bus.latencies`);
- :class:`MoveRecord`: a finished move (:meth:`zkzap.api.zap.Moved.as_dict`).
"""

from __future__ import annotations

from typing import Optional, TypedDict

__all__ = ["ScanRecord", "Identity", "RegisterRow", "RegisterValue", "Latency", "MoveRecord"]


class Identity(TypedDict):
    """``model`` (model number), ``firmware`` and ``return_mode`` (feedback-return-mode 0, 1 or
    2): None where the actuator did not say (never a guess); ``status`` ``ok``, ``error``,
    ``garbled``, ``duplicate`` or ``unidentified``; ``errors``: the error bits and doubts, in
    words."""

    model: Optional[int]
    firmware: Optional[int]
    return_mode: Optional[int]
    status: str
    errors: list[str]


class ScanRecord(Identity):
    """An :class:`Identity` with the actuator's ``id`` and the ``baud`` rate it answered at."""

    id: int
    baud: int


class _Register(TypedDict):
    id: int
    register: str
    address: int
    value: int


class _RegisterRow(_Register):
    access: str
    memory: str


class RegisterRow(_RegisterRow, total=False):
    """``id``, ``register`` (its name), ``address``, ``value`` (raw), ``access`` (``R``/``RW``),
    ``memory`` (``NV`` stored, ``V`` volatile, ``""`` read-only); ``physical`` and ``unit`` for
    a scaled register, ``unit`` for one with a unit, ``meaning`` for a coded value."""

    physical: float
    unit: str
    meaning: str


class _RegisterValue(_Register):
    errors: list[str]


class RegisterValue(_RegisterValue, total=False):
    """``id``, ``register``, ``address``, ``value`` and the reply's ``errors``; ``physical``,
    ``unit`` and ``meaning`` as in :class:`RegisterRow`."""

    physical: float
    unit: str
    meaning: str


class Latency(TypedDict):
    """``latency_ms`` (smoothed, from a request's last byte to the reply's first),
    ``variation_ms``, ``samples`` (answers measured) and ``late`` (answers after the learned
    timeout)."""

    latency_ms: float
    variation_ms: float
    samples: int
    late: int


class MoveRecord(TypedDict):
    """``id``, ``requested`` (the goal sent), ``goal`` (the one the actuator holds after its
    stroke limits), ``clamped`` and ``position`` (where the rod stopped)."""

    id: int
    requested: int
    goal: int
    clamped: bool
    position: int
