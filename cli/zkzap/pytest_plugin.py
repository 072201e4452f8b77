"""pytest fixtures for testing your own code against the zkzap simulators.

Installed with zkzap (a ``pytest11`` entry point), so in any project's tests:

.. code-block:: python

    def test_my_controller(zap_sim):
        with zkzap.Bus(zap_sim.url) as bus:
            my_controller(bus)
            assert bus[1].present_position > 0

    @pytest.mark.zap_sim(ids=[1, 2, 3], return_mode=2, transport="pty")
    def test_three(zap_sim): ...

    @pytest.mark.zk_sim(protocol_version=4, speed=20)
    def test_ecu(zk_sim): ...

    @pytest.mark.zap_sim(replay="tests/data/field.pcapng")   # a field problem, on the desk
    def test_the_field_problem(zap_sim): ...

``zap_sim`` is :func:`zkzap.sim.start_zap` (default: actuator ID 1, or with ``replay`` the
IDs that answered in the recording; in-process), ``zk_sim``
:func:`zkzap.sim.start_zk` (default: ten times real time, in-process); the marker's keyword
arguments are passed on. Each test gets a fresh simulator, stopped afterwards.
"""

from __future__ import annotations

import pytest

TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, Callable, Iterator

    from .sim.launch import Simulator


def pytest_configure(config: pytest.Config) -> None:
    """Register the ``zap_sim`` and ``zk_sim`` markers."""
    config.addinivalue_line("markers", "zap_sim(**options): options for the zap_sim fixture "
                                       "(zkzap.sim.start_zap: ids, baud, return_mode, faults, transport, replay, ...)")
    config.addinivalue_line("markers", "zk_sim(**options): options for the zk_sim fixture "
                                       "(zkzap.sim.start_zk: protocol_version, speed, error, transport, replay, ...)")


def _options(request: pytest.FixtureRequest, name: str, start: Callable[..., Simulator],
             defaults: dict[str, Any]) -> dict[str, Any]:
    """The marker's options over ``defaults``, checked against ``start``'s keyword arguments: a
    misspelt one is an :class:`~zkzap.errors.InvalidValue` naming the closest."""
    import inspect

    from .errors import InvalidValue, unknown_name

    marker = request.node.get_closest_marker(name)
    given = dict(marker.kwargs) if marker is not None else {}
    if marker is not None and marker.args:
        raise InvalidValue(f"@pytest.mark.{name}: takes keyword arguments only (like ids=[1, 2]); "
                           f"got {', '.join(repr(a) for a in marker.args)}")
    allowed = list(inspect.signature(start).parameters)
    for key in given:
        if key not in allowed:
            raise unknown_name(f"@pytest.mark.{name}", key, allowed, noun="option",
                               otherwise=f"; allowed {', '.join(allowed)}")
    if given.get("replay") is not None:        # a recording brings its own actuators
        defaults = {k: v for k, v in defaults.items() if k != "ids"}
    return {**defaults, **given}


@pytest.fixture
def zap_sim(request: pytest.FixtureRequest) -> Iterator[Simulator]:
    """A running actuator-bus simulator (:class:`zkzap.sim.launch.Simulator`); open ``.url``."""
    from zkzap.sim import start_zap

    with start_zap(**_options(request, "zap_sim", start_zap, {"ids": (1,)})) as sim:
        yield sim


@pytest.fixture
def zk_sim(request: pytest.FixtureRequest) -> Iterator[Simulator]:
    """A running ECU simulator (:class:`zkzap.sim.launch.Simulator`); open ``.url``."""
    from zkzap.sim import start_zk

    with start_zk(**_options(request, "zk_sim", start_zk, {"speed": 10.0})) as sim:
        yield sim
