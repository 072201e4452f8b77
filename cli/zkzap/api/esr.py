"""Answering the ECU's request for the air pressure (status ID 8, ESR = b4[5]) with control ID 8.

The protocol documents give no rate. zkzap answers the moment a status ID 8 frame shows ESR set
and the pressure is known, then once every :data:`INTERVAL_S` seconds of session time while the
ECU keeps asking (an ECU that did not take the first answer gets it again a second later; one
that is answered clears ESR and hears nothing more). At 20 Hz an ECU cycling ten status IDs
shows ID 8 twice a second, so a request is answered within half a second.

The answers keep a schedule: the next one is due a second after the one before was *due*, not
after it was sent, so requests that come late by a read slice still get one answer a second
(ten in ten seconds, not one every 1.5 s). Two answers are never closer than :data:`MIN_GAP_S`;
after a pause in the requests longer than a second the schedule starts again from the next one.

The pressure is a number (``--air-pressure 1008``) or an external barometer's field
(``--air-pressure baro_hpa``, see :mod:`zkzap.api.aux`), in hPa, rounded to the field's 1 hPa;
the field has 10 bits (0..1023 hPa), so a higher pressure is sent as 1023 (said once). Every
frame sent is kept (:attr:`PressureAnswer.sent`: time, hPa, frame), reported in the summary
and, like every control frame, published to the bridges and an MCAP log and recorded in a
``--capture``.
"""

from __future__ import annotations

from ..codec import zk

#: Time between two answers while ESR stays set (session seconds): once a second, on a schedule.
INTERVAL_S = 1.0
#: Frame times jitter by a read slice: an answer is sent from this long before it is due.
EARLY_S = 0.1 * INTERVAL_S
#: The least time between two answers (catching up with the schedule after a late request).
MIN_GAP_S = 0.5 * INTERVAL_S
#: Highest pressure control ID 8 carries (10 bits).
MAX_HPA = 1023


class PressureAnswer:
    """Answers ESR; ``pressure(t)`` gives the pressure to send (hPa) or None (not known yet)."""

    def __init__(self, pressure, describe, notify=None):
        self.pressure = pressure
        self.describe = describe
        self.notify = notify or (lambda message: None)
        self.sent = []                 # (t, hPa, frame hex)
        self.asked = 0                 # status ID 8 frames with ESR set
        self._due = None               # when the next answer is due (None: at once)
        self._last = None              # when the last one was sent
        self._told_unknown = False
        self._told_clamp = False

    def on_frame(self, t, rec):
        """The control ID 8 frame to send for this status frame, or None."""
        if rec.get("id") != 8 or not rec.get("esr"):
            return None
        self.asked += 1
        if self._due is not None and (t < self._due - EARLY_S or t - self._last < MIN_GAP_S):
            return None
        hpa = self.pressure(t)
        if hpa is None:
            if not self._told_unknown:
                self._told_unknown = True
                self.notify(f"the ECU asks for the air pressure (ESR) at t={t:.2f} s; no value from {self.describe} "
                            f"yet: it is answered once there is one")
            return None
        value = int(round(hpa))
        if value > MAX_HPA or value < 0:
            if not self._told_clamp:
                self._told_clamp = True
                self.notify(f"air pressure {hpa:g} hPa does not fit control ID 8 (10 bits, 0..{MAX_HPA} hPa): "
                            f"sent as {min(max(value, 0), MAX_HPA)}")
            value = min(max(value, 0), MAX_HPA)
        frame = zk.encode_control("pressure", pressure_hpa=value)[0]
        if not self.sent:
            self.notify(f"the ECU asks for the air pressure (ESR): answering {value} hPa from {self.describe} "
                        f"({frame.hex(' ').upper()}), at most once every {INTERVAL_S:g} s while it asks")
        on_time = self._due is not None and t - self._due < INTERVAL_S
        self._due, self._last = (self._due if on_time else t) + INTERVAL_S, t
        self.sent.append((round(t, 3), value, frame.hex(" ").upper()))
        return frame

    def summary(self) -> dict:
        """``air_pressure_answers`` for the run summary: how often the ECU asked and every frame sent."""
        return {"asked": self.asked, "sent": len(self.sent), "source": self.describe,
                "frames": [{"t": t, "pressure_hpa": v, "frame": f} for t, v, f in self.sent]}
