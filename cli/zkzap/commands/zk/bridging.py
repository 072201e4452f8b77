"""The bridge options of the ZK logging commands (``zk monitor``, ``zk send --for``,
``zk profile``): ``--mavlink``, ``--mqtt`` and their settings.

The options are checked as they are parsed (a malformed URL or a missing extra is exit 2 before
any port opens) and kept in the click context, so the commands' own signatures do not change;
:func:`start_bridges` builds and connects the bridges the command line asked for. Nothing here
imports pymavlink or paho-mqtt: the bridge modules do, when started.
"""

from __future__ import annotations

import click

from ...errors import UsageError
from ..options import FiniteRange, IntRange, apply_options

_META = "zkzap.bridges"

MAVLINK_HELP = ("Also send the telemetry as MAVLink to URL (any pymavlink connection: udpout:HOST:PORT, "
                "udpin:HOST:PORT, tcp:HOST:PORT, a serial device[,BAUD]): HEARTBEAT at 1 Hz, EFI_STATUS at "
                "--mavlink-rate, NAMED_VALUE_FLOAT, STATUSTEXT on engine state and error changes. Needs "
                "zkzap[mavlink].")
MQTT_HELP = ("Also publish every record as JSON to an MQTT broker: mqtt[s]://[user[:password]@]host[:port]/prefix "
             "(topics PREFIX/<kind>/<id>, retained PREFIX/state online/offline; password also from "
             "ZKZAP_MQTT_PASSWORD). Needs zkzap[mqtt].")

_MAVLINK_PREFIXES = ("udp:", "udpin:", "udpout:", "udpbcast:", "tcp:", "tcpin:", "mcast:")
_WITH_MAVLINK = {"mavlink_rate": "--mavlink-rate", "sysid": "--sysid", "compid": "--compid",
                 "ecu_index": "--ecu-index"}
_WITH_MQTT = {"mqtt_qos": "--mqtt-qos", "mqtt_optional": "--mqtt-optional"}


def _store(ctx, param, value):
    if value is None or value is False:
        return value
    ctx.meta.setdefault(_META, {})[param.name] = value
    return value


def check_mavlink_url(url: str) -> str:
    """A pymavlink connection string: NET:HOST:PORT with a valid port, or a serial device."""
    from ...io.bridges import require_extra

    require_extra("pymavlink", "mavlink", "mavlink")
    low = url.lower()
    if low.startswith(_MAVLINK_PREFIXES):
        rest = url.split(":", 1)[1]
        host, sep, port = rest.rpartition(":")
        listening = low.startswith(("udpin:", "tcpin:", "udp:"))    # may omit the host: every address
        if not sep or not port.isdigit() or not 0 < int(port) < 65536 or not (host or listening):
            raise UsageError(f"mavlink: {url}: expected {url.split(':', 1)[0]}:HOST:PORT (port 1..65535)")
        return url
    device = url.split(",", 1)
    if url.startswith(("/", "COM", "com")) and device[0]:
        if len(device) == 2 and not device[1].isdigit():
            raise UsageError(f"mavlink: {url}: the baud rate after ',' must be a number")
        return url
    raise UsageError(f"mavlink: {url}: expected udpout:HOST:PORT, udpin:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT "
                     f"or a serial device (/dev/ttyUSB1,57600)")


def _mavlink(ctx, param, value):
    if value is not None:
        check_mavlink_url(value)
    return _store(ctx, param, value)


def _mqtt(ctx, param, value):
    if value is not None:
        from ...io.bridges import require_extra
        from ...io.bridges.mqtt import MqttUrl

        require_extra("paho", "mqtt", "mqtt")
        if MqttUrl(value).password_in_url:
            from ...io.bridges.mqtt import PASSWORD_ENV
            from ..options import warn

            warn(f"mqtt: the password in the URL can be read by every user of this computer in the process "
                 f"list (ps); give it in {PASSWORD_ENV} instead")
    return _store(ctx, param, value)


def bridge_options(f):
    """The bridge options, in help order."""
    opts = [
        click.option("--mavlink", metavar="URL", default=None, expose_value=False, callback=_mavlink,
                     help=MAVLINK_HELP),
        click.option("--mavlink-rate", type=FiniteRange(0.1, 100), default=None, metavar="HZ",
                     expose_value=False, callback=_store, help="EFI_STATUS messages per second (default 10)."),
        click.option("--sysid", type=IntRange(1, 255), default=None, metavar="N", expose_value=False,
                     callback=_store, help="MAVLink system ID (default 1: the aircraft's own)."),
        click.option("--compid", type=IntRange(1, 255), default=None, metavar="N", expose_value=False,
                     callback=_store, help="MAVLink component ID (default 158, MAV_COMP_ID_PERIPHERAL)."),
        click.option("--ecu-index", type=IntRange(0, 255), default=None, metavar="N", expose_value=False,
                     callback=_store, help="EFI_STATUS ecu_index, for more than one engine (default 0)."),
        click.option("--mqtt", metavar="URL", default=None, expose_value=False, callback=_mqtt, help=MQTT_HELP),
        click.option("--mqtt-qos", type=IntRange(0, 2), default=None, metavar="0|1|2", expose_value=False,
                     callback=_store, help="MQTT quality of service of the records (default 0)."),
        click.option("--mqtt-optional", is_flag=True, default=False, expose_value=False, callback=_store,
                     help="Run even when the broker is unreachable at the start (records queue, then drop, "
                          "until it answers); without it that is exit 4."),
    ]
    return apply_options(f, opts)


def requested() -> dict:
    """The bridge options given on this command line (checked for consistency)."""
    ctx = click.get_current_context(silent=True)
    given = dict(ctx.meta.get(_META, {})) if ctx is not None else {}
    for group, option, main in ((_WITH_MAVLINK, "--mavlink", "mavlink"), (_WITH_MQTT, "--mqtt", "mqtt")):
        if main not in given:
            for name, spelled in group.items():
                if name in given:
                    raise UsageError(f"{spelled.lstrip('-')}: applies only with {option}")
    return given


def refuse_without(why: str) -> None:
    """Refuse bridge options on a command line that logs nothing (``zk send`` without --for)."""
    given = requested()
    if given:
        name = next(iter(given))
        raise UsageError(f"{name.replace('_', '-')}: applies only with {why}")


class _NoBridges:
    """No bridge asked for (the bridge modules stay unimported)."""

    def __bool__(self):
        return False

    def close(self):
        pass

    def stats(self):
        return {}


def make_bridges(given=None, notify=None):
    """The bridges asked for (not started): a :class:`~zkzap.io.bridges.Bridges`, or a falsy
    stand-in when there are none."""
    given = requested() if given is None else given
    if not given:
        return _NoBridges()
    from ...io.bridges import Bridges

    out = []
    if "mavlink" in given:
        from ...io.bridges import mavlink

        out.append(mavlink.MavlinkBridge(given["mavlink"], rate=given.get("mavlink_rate", mavlink.DEFAULT_RATE),
                                         sysid=given.get("sysid", mavlink.DEFAULT_SYSID),
                                         compid=given.get("compid", mavlink.DEFAULT_COMPID),
                                         ecu_index=given.get("ecu_index", 0)))
    if "mqtt" in given:
        from ...io.bridges import mqtt

        out.append(mqtt.MqttBridge(mqtt.MqttUrl(given["mqtt"]), qos=given.get("mqtt_qos", 0),
                                   optional=given.get("mqtt_optional", False), notify=notify))
    return Bridges(out)
