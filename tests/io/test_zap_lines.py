"""ZapLines renders exactly what the record writers write, memo or not."""

from __future__ import annotations

import io

from hypothesis import given, settings
from hypothesis import strategies as st

from zkzap.codec import zap
from zkzap.io.writers import CsvWriter, JsonlWriter, csv_dialect, json_dialect
from zkzap.io.zap_lines import ZapLines

COLUMNS = list(zap.ZAP_KEYS) + ["frame"]

packets = st.one_of(
    st.builds(lambda i, r: zap.load(i, r), st.integers(0, 4), st.sampled_from(["present-position", "model-number",
                                                                              "present-voltage", 0x40])),
    st.builds(lambda i, e, d: zap.packet(i, e, d), st.integers(0, 4), st.sampled_from([0, 1, 0x20, 0x21]),
              st.binary(max_size=4)),
    st.builds(lambda i, v: zap.store(i, "goal-position", v), st.integers(0, 4), st.integers(0, 4095)),
    st.builds(lambda t: zap.symmetric_store("goal-speed", t)[0],
              st.dictionaries(st.integers(0, 9), st.integers(0, 1023), min_size=1, max_size=3)),
    st.builds(zap.echo, st.integers(0, 4)),
)


def by_writer(pkts, writer_cls, *args):
    out = io.StringIO()
    w = writer_cls(out, *args)
    dec = zap.ZapDecoder()
    for p in pkts:
        rec = dec.decode(p)
        rec["frame"] = p.hex(" ").upper()
        w.write(rec)
    w.close()
    return out.getvalue()


@settings(max_examples=150, deadline=None)
@given(st.lists(packets, max_size=40), st.integers(1, 8))
def test_lines_equal_the_writers_records(pkts, cache):
    for dialect, cls, args in ((json_dialect(), JsonlWriter, ()), (csv_dialect(COLUMNS), CsvWriter, (COLUMNS,))):
        lines = ZapLines(zap.ZapDecoder(), dialect, cache=cache)
        got = "".join(line + "\n" for line in lines.encode_all(pkts))
        expected = by_writer(pkts, cls, *args)
        if cls is CsvWriter:
            expected = expected.split("\n", 1)[1]
        assert got == expected
