"""Taps on a logging session for the bridges and the MCAP log: every record also goes to the
bridges, every control frame the session sends becomes a control record (for the bridges and an
MCAP file's control channels), and the health view carries the bridges' figures."""

from __future__ import annotations


class _TappedSource:
    """A session source whose writes (control frames) are also recorded."""

    def __init__(self, source, on_frame):
        self._source = source
        self._on_frame = on_frame

    def __getattr__(self, name):
        return getattr(self._source, name)

    def write(self, frame):
        self._source.write(frame)
        self._on_frame(frame)


def tap_session(source, tel, out, bridges, on_update, write):
    """(source, sink, on_update) for :class:`~zkzap.api.session.Session`; ``write``: the
    session's sink of the records (each record still goes through it once, then to the
    bridges)."""
    from ...codec import zk

    decoder = zk.ZkDecoder()
    mcap = out.writer if out.fmt == "mcap" else None
    submit = bridges.submit if bridges else None
    lane = getattr(out, "lane", None)
    if mcap is not None:              # the control records, in the records' lane (off the control path)
        mcap = lane.wrap(mcap.write) if lane is not None else mcap.write

    def on_frame(frame):
        t = source.now()
        rec = {"time": source.clock.iso(t), "t": round(t, 3)}
        rec.update(decoder.decode(frame))
        rec["frame"] = frame.hex(" ").upper()
        if mcap is not None:
            mcap(rec)
        if submit is not None:
            submit(rec)

    if submit is not None:
        def sink(rec):
            write(rec)
            submit(rec)
    else:
        sink = write
    if on_update is not None and bridges:
        inner = on_update

        def on_update(snapshot, health):
            inner(snapshot, dict(health, bridges=bridges.stats()))
    return _TappedSource(source, on_frame), sink, on_update
