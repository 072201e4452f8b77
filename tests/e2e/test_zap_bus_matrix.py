"""The zap command set on slow, trickling and echoing buses in every return mode, over real ptys,
checked against the half-duplex discipline in what each run captured.

The command x bus matrix (latencies 2, 18, 22, 25, 40, 60, 100 and 140 ms; with and without
1 ms between reply bytes; with and without an echoing adapter; return modes 0, 1 and 2) is
covered lean: one bus per latency, their gaps, echoes and modes chosen so that every pair of
those three comes up (an orthogonal array), each bus running a batch or a shell of commands,
every command on fast and slow buses, and one command that searches the bus. The whole matrix,
every command on every bus, is benchmarks/bus_matrix.py.

Nothing here depends on how fast the machine is. What is checked is the discipline itself, on
the host's own clock (the capture's timestamps, see :mod:`buscheck`): no request while a reply
is still due, each reply the answer to the request before it, a retry only after a window
closed unanswered, the round trips the commands print the ones the capture shows, and no
collision on the simulated line. A simulator held up by a loaded machine answers late, which
the policy allows for: the commands run with a window of half a second (--timeout), so that a
simulator held up on a loaded machine is still answered within it (the searches keep the
default). The default window against actuators up to 140 ms late is tested in-process
(tests/link/test_zap_timing.py), where nothing can hold the simulator up.
"""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from zkzap.api.sniff import ZapSniffer

from .buscheck import LINES, check_capture, check_rtts, frames
from .conftest import _first_line, clean_env, executable, stop_sim

#: (latency ms, gap ms, echo, mode, runner, lines, search): gap x echo x mode pairs all appear.
BUSES = [
    (2, 0, False, 1, "batch", ["echo", "load", "store", "dump", "backup", "apply", "diff", "watch", "move",
                               "sync-move", "check"], ["scan", "--ids", "0-4"]),
    (18, 1, True, 2, "shell", ["echo", "load", "store", "dump", "watch", "check-still", "sync-move"],
     ["backup", "-o", "{tmp}/all.json"]),
    (22, 1, False, 0, "batch", ["echo", "store", "move-nowait", "sync-nowait"], ["scan", "--ids", "0-4"]),
    (25, 0, True, 0, "shell", ["echo", "store", "sync-nowait"], None),
    (40, 0, False, 2, "batch", ["echo", "load", "store", "backup", "apply", "diff", "move"],
     ["diff", "{tmp}/fleet.json", "bus"]),
    (60, 1, True, 1, "batch", ["echo", "load", "dump", "watch", "sync-move", "check-still"],
     ["scan", "--ids", "0-4"]),
    (100, 0, True, 1, "shell", ["echo", "load", "store", "move"], None),
    (140, 1, False, 2, "batch", ["echo", "load", "store", "sync-move"], ["scan", "--ids", "0-3"]),
]


class Sim:
    """``zkzap sim zap`` on a pty, its stderr (collisions) kept in a file."""

    def __init__(self, args, tmp):
        self.err = open(tmp / "sim.err", "w+")
        self.proc = subprocess.Popen([executable("zkzap"), "sim", "zap", "--pty", *args], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, stderr=self.err, env=clean_env())
        self.url = _first_line(self.proc, 10.0)

    def stop(self) -> str:
        stop_sim(self.proc)
        self.err.seek(0)
        text = self.err.read()
        self.err.close()
        return text


def run(args, input=None):
    p = subprocess.run(args, input=input, capture_output=True, text=True, timeout=120, env=clean_env())
    return p.returncode, p.stdout, p.stderr


@pytest.mark.parametrize("latency,gap,echo,mode,runner,lines,search", BUSES,
                         ids=[f"{b[0]}ms-gap{b[1]}-{'echo' if b[2] else 'noecho'}-mode{b[3]}-{b[4]}" for b in BUSES])
def test_commands_keep_the_half_duplex_discipline(tmp_path, latency, gap, echo, mode, runner, lines, search):
    sim = Sim(["--ids", "1,2", "--turnaround", str(latency), "--gap", str(gap), "--return-mode", str(mode)]
              + (["--echo"] if echo else []), tmp_path)
    window = 0.5
    link = ["-p", sim.url, "--return-mode", str(mode)]
    try:
        text = "".join(LINES[name][0].format(tmp=tmp_path) + "\n" for name in lines)
        cap = tmp_path / "run.pcapng"
        if runner == "batch":
            (tmp_path / "lines.txt").write_text(text)
            code, out, err = run([executable("zap"), "batch", str(tmp_path / "lines.txt"), *link, "--yes",
                                  "--timeout", str(window), "--capture", str(cap)])
            records = [json.loads(x) for x in out.splitlines()]
            assert code == 0 and [r["exit"] for r in records] == [0] * len(lines), (out, err)
        else:
            code, out, err = run([executable("zkzap"), "shell", "zap", *link, "--timeout", str(window),
                                  "--capture", str(cap)], input=text + "exit\n")
            records = []
            assert code == 0 and "error:" not in err, (out, err)
        pairs, retries = check_capture(cap, mode, window=window)
        unanswered = [(p.request.hex(" "), p.sent) for p in pairs if p.reply is None]
        assert pairs and not unanswered, unanswered
        # the round trips the echo line printed are its requests' in the capture (it runs first)
        shown = [rec["rtt_ms"] for r in records if r["command"].startswith("echo") for rec in r["result"]]
        check_rtts(pairs, shown, 1, latency)
        # the sniffer pairs every reply with the request it answers
        sniffer = ZapSniffer([("capture", "both")], 57600)
        got = frames(cap)
        sniffer.wall0 = got[0][0]
        paired = [rec for ts, _, pkt in got for rec in sniffer.frame(ts, 0, pkt) if rec["kind"] == "feedback"]
        bad = [rec for rec in paired if rec["pairing"] != "ok" or rec["latency_ms"] < latency]
        assert paired and not bad, [(r["pairing"], r.get("latency_ms"), r.get("request"), r["id"]) for r in bad]
        sim.err.flush()
        said = (tmp_path / "sim.err").read_text()
        assert "collision" not in said, said               # nothing met a reply on the line
        if search is not None:         # a search's first pass may move on early: only what it finds counts
            code, out, err = run([executable("zap"), *[a.format(tmp=tmp_path) for a in search], *link])
            assert code == 0, err
            if search[0] == "scan":
                found = [json.loads(x) for x in out.splitlines()]
                assert [(r["id"], r["status"], r["return_mode"]) for r in found] == [(1, "ok", mode), (2, "ok", mode)]
    finally:
        sim.stop()
