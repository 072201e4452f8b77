"""Serial ports present on this machine, with what is worth knowing about their USB adapters.

:func:`port_records` turns pyserial's ``list_ports.comports()`` into plain records (device,
description, VID:PID, serial number, chip, stable /dev/serial/by-id name, FTDI latency timer)
with hints: an FTDI adapter's latency timer (16 ms by default on Linux, the usual cause of slow
request/reply tools) and how to set it to 1 ms; CH34x adapters (IR Robot's own) have none; a
device the user may not open. The sysfs and /dev roots are parameters so tests can fake them.
"""

from __future__ import annotations

import os
import sys

SYSFS_USB_SERIAL = "/sys/bus/usb-serial/devices"
DEV_BY_ID = "/dev/serial/by-id"

FTDI_VID = 0x0403
#: FTDI product IDs -> chip.
FTDI_CHIPS = {0x6001: "FT232R/FT245R", 0x6010: "FT2232", 0x6011: "FT4232", 0x6014: "FT232H", 0x6015: "FT-X"}
WCH_VID = 0x1A86
#: WCH product IDs -> chip (CH340/CH341 and the CH9102 with the same driver family).
WCH_CHIPS = {0x7523: "CH340", 0x7522: "CH340", 0x5523: "CH341", 0x55D4: "CH9102", 0x55D3: "CH343"}
OTHER_CHIPS = {(0x10C4, 0xEA60): "Silicon Labs CP210x", (0x067B, 0x2303): "Prolific PL2303"}

UDEV_RULE = 'ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", ATTR{latency_timer}="1"'


def chip_of(vid, pid):
    if vid is None:
        return None
    if vid == FTDI_VID:
        return "FTDI " + FTDI_CHIPS.get(pid, "USB serial")
    if vid == WCH_VID:
        return "WCH " + WCH_CHIPS.get(pid, "CH34x")
    return OTHER_CHIPS.get((vid, pid))


def read_latency_timer(name, sysfs=SYSFS_USB_SERIAL):
    """The FTDI latency timer of ``ttyUSBn`` in ms, or None when the driver exposes none."""
    try:
        with open(os.path.join(sysfs, name, "latency_timer"), encoding="ascii") as f:
            return int(f.read().strip())
    except (OSError, ValueError):
        return None


def by_id_links(dev_by_id=DEV_BY_ID):
    """{real device path: stable /dev/serial/by-id path}."""
    out = {}
    try:
        names = sorted(os.listdir(dev_by_id))
    except OSError:
        return out
    for name in names:
        link = os.path.join(dev_by_id, name)
        out.setdefault(os.path.realpath(link), link)
    return out


#: Where Windows keeps the FTDI latency timer (the driver's advanced port settings).
WINDOWS_FTDI = ("FTDI adapter: set its latency timer to 1 ms for fast replies (the default 16 ms delays every "
                "reply): Device Manager > Ports (COM & LPT) > USB Serial Port > Properties > Port Settings > "
                "Advanced > Latency Timer (msec)")
MACOS_FTDI = ("FTDI adapter: the latency timer (16 ms by default with FTDI's VCP driver) is set in the "
              "driver's Info.plist (LatencyTimer); Apple's own driver (AppleUSBFTDI) uses a short one")
MACOS_CH34X = ("CH34x adapter (the chip of IR Robot's own USB adapter): macOS 11 (Big Sur) and later have a "
               "driver built in (/dev/cu.usbserial-*); older macOS versions need WCH's vendor driver "
               "(CH34xVCPDriver)")


def _set_timer(path) -> str:
    return (f"set 1 ms: echo 1 | sudo tee {path} (until unplugged; to keep it, add the udev rule "
            f"{UDEV_RULE} to /etc/udev/rules.d/99-ftdi-latency.rules), or pass --low-latency")


def latency_timer_hint(device, timer_ms, sysfs=None) -> str:
    """How to lower the latency timer of the FTDI adapter behind ``device`` (one line)."""
    name = os.path.basename(os.path.realpath(str(device)))
    path = os.path.join(SYSFS_USB_SERIAL if sysfs is None else sysfs, name, "latency_timer")
    return f"its latency timer is {timer_ms} ms; " + _set_timer(path)


def hints_for(rec, sysfs=SYSFS_USB_SERIAL, platform=None):
    """Advice for one port record (a list of one-line strings). ``platform`` is a
    ``sys.platform`` value (default: this machine's): the advice differs on Windows and macOS."""
    platform = sys.platform if platform is None else platform
    hints = []
    name = rec["name"]
    if rec["vid"] == FTDI_VID and platform.startswith("win"):
        hints.append(WINDOWS_FTDI)
    elif rec["vid"] == FTDI_VID and platform == "darwin":
        hints.append(MACOS_FTDI)
    elif rec["vid"] == WCH_VID and platform == "darwin":
        hints.append(MACOS_CH34X)
    elif rec["vid"] == FTDI_VID:
        lt = rec["latency_timer_ms"]
        path = os.path.join(sysfs, name, "latency_timer")
        if lt is None:
            hints.append("FTDI adapter: set its latency timer to 1 ms in the driver settings for fast replies "
                         "(the default 16 ms delays every reply)")
        elif lt > 1:
            hints.append(f"FTDI latency timer is {lt} ms, so every reply waits up to {lt} ms in the adapter; "
                         + _set_timer(path))
        else:
            hints.append(f"FTDI latency timer is {lt} ms (fastest)")
    elif rec["vid"] == WCH_VID:
        hints.append("CH34x adapter (the chip of IR Robot's own USB adapter): no latency timer to set")
    tty_hint = outgoing_port_hint(rec["device"], platform)
    if tty_hint:
        hints.append(tty_hint)
    if rec["permission"] is False and not platform.startswith("win"):
        group = rec.get("group")
        who = f"the group '{group}'" if group else "the device's group"
        hints.append(f"no read/write permission on {rec['device']}: add yourself to {who} "
                     f"(sudo usermod -aG {group or 'dialout'} $USER) and log in again")
    return hints


def outgoing_port_hint(device, platform=None):
    """A hint for a port name that is wrong for an outgoing connection, or None: on macOS,
    ``/dev/tty.*`` waits for a carrier-detect signal that an adapter to an ECU or an actuator
    bus never raises; ``/dev/cu.*`` is the calling-unit device for the same adapter."""
    platform = sys.platform if platform is None else platform
    dev = str(device or "")
    if platform == "darwin" and dev.startswith("/dev/tty.") and not dev.startswith("/dev/tty.Bluetooth"):
        return (f"{dev} is the dial-in device: opening it can wait for carrier detect; use "
                f"/dev/cu.{dev[len('/dev/tty.'):]} for an outgoing connection")
    return None


def _group_of(path):
    try:
        import grp

        return grp.getgrgid(os.stat(path).st_gid).gr_name
    except (ImportError, KeyError, OSError):
        return None


def port_record(info, sysfs=SYSFS_USB_SERIAL, links=None, platform=None) -> dict:
    """A record for one pyserial ``ListPortInfo``."""
    vid, pid = info.vid, info.pid
    name = getattr(info, "name", None) or os.path.basename(info.device)
    exists = os.path.exists(info.device)
    rec = {
        "device": info.device,
        "name": name,
        "description": None if info.description in (None, "n/a") else info.description,
        "vid_pid": f"{vid:04X}:{pid:04X}" if vid is not None and pid is not None else None,
        "vid": vid,
        "pid": pid,
        "serial_number": info.serial_number,
        "manufacturer": info.manufacturer,
        "product": info.product,
        "location": info.location,
        "chip": chip_of(vid, pid),
        "by_id": (links or {}).get(os.path.realpath(info.device)),
        "latency_timer_ms": read_latency_timer(name, sysfs) if vid == FTDI_VID else None,
        "permission": os.access(info.device, os.R_OK | os.W_OK) if exists else None,
        "group": _group_of(info.device) if exists else None,
    }
    rec["hints"] = hints_for(rec, sysfs, platform)
    return rec


def port_records(comports=None, *, usb_only=False, sysfs=SYSFS_USB_SERIAL, dev_by_id=DEV_BY_ID, platform=None):
    """Records for every serial port pyserial finds, sorted by device (USB adapters only with
    ``usb_only``). ``comports`` defaults to ``serial.tools.list_ports.comports()``."""
    if comports is None:
        from serial.tools import list_ports

        comports = list_ports.comports()
    links = by_id_links(dev_by_id)
    out = []
    for info in sorted(comports, key=lambda p: p.device):
        if usb_only and info.vid is None:
            continue
        out.append(port_record(info, sysfs, links, platform))
    return out
