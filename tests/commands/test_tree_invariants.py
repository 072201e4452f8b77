"""Invariants that hold for every command of the click tree (tests/cmdtree.py), found by walking
it, never by a list of commands:

- **bad input sends nothing**: every parameter whose declared type has a domain (choices, a
  range, IDs, registers, files...) is given a value outside it, on an otherwise valid command
  line; the command exits 2 with nothing on stdout, nothing reaches its port (a TCP port that
  records every connection), and every existing output file stays byte for byte as it was.
  The same line is refused by the check a batch runs (:mod:`zkzap.checking`), so a batch and
  a single command agree;
- **a valid command line passes that check** (it is what the bad lines are built from).

A valid command line is built from the declared types too: a value each type takes, the input
files by what an :class:`~zkzap.commands.options.InputPath` holds, every port option pointed
at the recording port, ``--yes`` where the command takes it, and every output option the
command accepts pointed at an existing file.
"""

from __future__ import annotations

import click
import pytest
from click.testing import CliRunner

from cmdtree import RecordingPort, bad_value, commands, spelling, valid_value
from zkzap.commands import root, run

OLD = b"old content\n"


def _params(cmd):
    return [p for p in cmd.params if p.expose_value or type(p.type).__name__ == "OutputPath"]


def _cases():
    out = []
    for path, cmd in commands():
        for p in _params(cmd):
            if bad_value(p) is not None:
                out.append((path, p.name))
    return out


CASES = _cases()


def test_the_walk_covers_the_tree():
    paths = {" ".join(path) for path, _ in CASES}
    for expected in ("zk send control", "zk monitor", "zk profile", "zap store", "zap apply", "zap setup",
                     "zap watch", "zap batch", "zk batch", "sniff zk", "sim zap", "shell zap", "zk report"):
        assert expected in paths
    assert len(CASES) > 300


@pytest.fixture(scope="module")
def port():
    p = RecordingPort()
    yield p
    p.close()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Valid input files by what they hold, and a factory of existing output files."""
    d = tmp_path_factory.mktemp("inputs")
    from zkzap import Bus
    from zkzap.api import fleet, logbook
    from zkzap.link.pcapng import INBOUND, OUTBOUND, Writer
    from zkzap.sim import start_zap

    out = {}
    (d / "stand.csv").write_text("0,20,run\n1,0,standby\n")
    out["schedule"] = str(d / "stand.csv")
    with start_zap(ids=[1]) as sim, Bus(sim) as bus:
        fleet.dump_document(fleet.read_bus(bus.link, [1]), str(d / "fleet.json"))
    out["fleet"] = str(d / "fleet.json")
    for proto, frames in (("zk", [(b"\xf1\x00\x00\x00\x00\x4c\xa0", INBOUND)]),
                          ("zap", [(bytes.fromhex("FFFFFF0102F10B"), OUTBOUND),
                                   (bytes.fromhex("FFFFFF010200FC"), INBOUND)])):
        w = Writer(str(d / f"{proto}.pcapng"))
        i = w.interface(proto, "/dev/ttyUSB0", 115200)
        for k, (data, direction) in enumerate(frames):
            w.packet(i, 1.0 + k / 100, data, direction)
        w.close()
        out[f"{proto} capture"] = str(d / f"{proto}.pcapng")
    (d / "token.txt").write_text("a-token-for-the-walk\n")
    out["token"] = str(d / "token.txt")
    (d / "limits.txt").write_text("rpm<=200000\n")
    out["limits"] = str(d / "limits.txt")
    (d / "run.csv").write_text("time,t,id,rpm,egt_c\n2026-01-01T00:00:00.000Z,0.0,1,0,20\n")
    out["run"] = str(d / "run.csv")
    (d / "steps.csv").write_text("step,mode\n")
    out["steps"] = str(d / "steps.csv")
    (d / "summary.json").write_text("{}\n")
    out["summary"] = str(d / "summary.json")
    logbook.record(str(d / "lb.db"), {"started": "2026-01-01T00:00:00Z", "ended": "2026-01-01T00:01:00Z",
                                      "duration_s": 60.0, "running_s": 0.0, "starts": 0, "command": "zk monitor",
                                      "port": "sim://zk", "files": [], "errors": [], "limits_violated": [],
                                      "outcome": "duration", "exit_status": 0})
    out["logbook"] = str(d / "lb.db")
    (d / "zk.txt").write_text("send keepalive\n")
    out["zk batch"] = str(d / "zk.txt")
    (d / "zap.txt").write_text("echo --id 1\n")
    out["zap batch"] = str(d / "zap.txt")
    (d / "path.csv").write_text("t,id,position\n0,1,100\n0.1,1,200\n")
    out["zap path"] = str(d / "path.csv")
    out["frames"] = str(d / "zk.pcapng")
    (d / "cell.log").write_text("raw=1.5\n" * 20)
    (d / "stand.toml").write_text(f'[[sensor]]\nsource = "{d / "cell.log"}"\n[[sensor.channel]]\nname = "raw"\n')
    out["sensors"] = str(d / "stand.toml")
    outs = d / "outputs"
    outs.mkdir()
    made = []

    def output(t):
        """A path for an output of type ``t``: an existing file (a logbook: empty; a state
        file: none yet, as a first run finds it)."""
        made.append(1)
        f = outs / f"out{len(made)}{(t.suffixes or ('.out',))[0]}"
        if t.kind == "database":
            f.write_bytes(b"")
        elif t.kind not in ("state", "link"):
            f.write_bytes(OLD)
        return str(f)

    out["output"] = output
    return out


def _invoke(args, *, check):
    """(exit status, stdout, stderr) of ``zkzap ARGS`` in-process; ``check``: as a batch checks."""
    from zkzap import checking

    runner = CliRunner()
    with runner.isolation(input="") as streams:
        code = 0
        if check:
            with checking.checking():
                code = run(root, "zkzap", list(args))
        else:
            code = run(root, "zkzap", list(args))
        return code, streams[0].getvalue().decode(), streams[1].getvalue().decode()


class Line:
    """A command line: positional values by parameter name, options by parameter."""

    def __init__(self, path, cmd):
        self.path, self.cmd = list(path), cmd
        self.args, self.opts = {}, {}

    def argv(self, replace=None):
        """The tokens, with ``replace`` = (parameter, value) substituted or added."""
        args, opts = dict(self.args), dict(self.opts)
        if replace is not None:
            p, v = replace
            (args if isinstance(p, click.Argument) else opts)[p.name] = (p, v)
        out = list(self.path)
        for p in self.cmd.params:
            if isinstance(p, click.Argument) and p.name in args:
                out.append(args[p.name][1])
        for name, (p, v) in opts.items():
            if v is True:
                out.append(spelling(p))
            else:
                out.append(f"{spelling(p)}={v}")
        return out


_LINES = {}


def _valid_line(path, cmd, files, port):
    """A command line every check of the command passes (cached per command), with every
    output option it accepts pointed at an existing file."""
    key = tuple(path)
    if key in _LINES:
        return _LINES[key]
    line = Line(path, cmd)
    for p in _params(cmd):
        if isinstance(p, click.Argument):
            v = valid_value(p, files)
            if v is None and p.required:
                pytest.fail(f"{' '.join(path)}: no valid value for argument {p.name} from its type {p.type!r}")
            if v is not None and (p.required or type(p.type).__name__ == "InputPath") and p.nargs != -1 or \
                    (p.nargs == -1 and p.required):
                line.args[p.name] = (p, v)
        elif "--port" in p.opts or p.name == "ports":
            line.opts[p.name] = (p, port.url)
        elif p.name == "yes" and p.is_flag:
            line.opts[p.name] = (p, True)
        elif p.required or (p.name == "ident" and p.default is None):   # an ID a write needs given
            v = valid_value(p, files)
            if v is None:
                pytest.fail(f"{' '.join(path)}: no valid value for {spelling(p)} from its type {p.type!r}")
            line.opts[p.name] = (p, v)
    outputs = [p for p in _params(cmd) if type(p.type).__name__ == "OutputPath" and isinstance(p, click.Option)
               and p.name not in line.opts]
    code, out, err = _invoke(line.argv(), check=True)
    for p in outputs if code else ():           # a command that needs an output (zk report -o)
        line.opts[p.name] = (p, valid_value(p, files))
        code, out, err = _invoke(line.argv(), check=True)
        if code == 0:
            break
        del line.opts[p.name]
    if code:
        code, out, err = _invoke(line.argv(), check=True)
    assert code == 0, f"{' '.join(line.argv())}: a line built from the declared types fails its check: {err}"
    for p in outputs:
        if p.name not in line.opts:
            line.opts[p.name] = (p, valid_value(p, files))
            if _invoke(line.argv(), check=True)[0] != 0:
                del line.opts[p.name]           # an output this line does not take (-o without --for)
    _LINES[key] = line
    return line


def _snapshot(line):
    """The output files of the line and what they hold now (None: absent)."""
    import os

    out = {}
    for name, (p, v) in line.opts.items():
        if type(p.type).__name__ == "OutputPath":
            out[v] = open(v, "rb").read() if os.path.isfile(v) else None
    return out


@pytest.mark.parametrize("path,name", CASES, ids=[f"{' '.join(p)} {n}" for p, n in CASES])
def test_bad_input_sends_nothing_and_touches_no_file(path, name, files, port):
    cmd = dict(commands())[tuple(path)]
    line = _valid_line(path, cmd, files, port)
    param = next(p for p in cmd.params if p.name == name)
    argv = line.argv((param, bad_value(param)))
    before_files, before_port = _snapshot(line), port.seen()
    code, out, err = _invoke(argv, check=True)
    assert code == 2, f"{' '.join(argv)}: the batch check lets it through (exit {code}): {err}"
    code, out, err = _invoke(argv, check=False)
    assert code == 2, f"{' '.join(argv)}: exit {code}: {err}"
    assert out == "", f"{' '.join(argv)}: stdout {out!r}"
    assert "Traceback" not in err
    assert port.seen() == before_port, f"{' '.join(argv)}: the port was reached"
    assert _snapshot(line) == before_files, f"{' '.join(argv)}: an output file changed"


# --- every output option survives a device, a FIFO, a symlink and its own input -------------

def _outputs():
    """(command path, output option name): one command per group, option spelling and kind
    (the sub-commands of a group share their options' code: ``zk send *``), every --capture
    once per protocol group."""
    seen, out = set(), []
    for path, cmd in commands():
        for p in _params(cmd):
            if type(p.type).__name__ != "OutputPath" or not isinstance(p, click.Option):
                continue
            group = path[:1] if p.type.kind == "capture" else path[:-1]
            key = (group, spelling(p), p.type.kind)
            if key not in seen:
                seen.add(key)
                out.append((path, p.name))
    return out


OUTPUTS = _outputs()


def test_the_output_walk_finds_every_kind():
    kinds = {next(p for p in dict(commands())[tuple(path)].params if p.name == name).type.kind
             for path, name in OUTPUTS}
    assert kinds == {"records", "bytes", "capture", "document", "database", "state", "link"}


def _sim_for(path):
    proto = "zk" if "zk" in path else "zap"
    # the mightyZAP simulator on its virtual clock: a census (backup, diff, set-id) listens out its
    # 1.5 s horizon in no time
    return "sim://zk?speed=50" if proto == "zk" else "sim://zap?ids=1&clock=virtual"


def _runnable(path, cmd, name, files, port):
    """A line that runs to its end on a simulator and writes output option ``name``: the valid
    line with the port a simulator, bounded (--count, --for, --duration) where it can be."""
    base = _valid_line(path, cmd, files, port)
    line = Line(path, cmd)
    line.args = dict(base.args)
    line.opts = {k: v for k, v in base.opts.items() if type(v[0].type).__name__ != "OutputPath"}
    by = {p.name: p for p in cmd.params}
    for pname in ("port", "ports"):
        if pname in line.opts:
            line.opts[pname] = (by[pname], _sim_for(path))
    out = by[name]
    probe = (out, files["output"](out.type))
    bounds = [("count", "3"), ("for_s", "0.5"), ("duration", "0.5"), ("no_move", True), ("no_wait", True)]
    bounds += [(p.name, "1") for p in cmd.params if type(p.type).__name__ == "IdList"
               and (p.default or p.name == "ids")]          # the actuators a command addresses: not all 254
    for pname, value in bounds:
        if pname in by and pname not in line.opts:      # a bound the line takes (--no-wait: not with --for)
            line.opts[pname] = (by[pname], value)
            if _invoke(line.argv(probe), check=True)[0]:
                del line.opts[pname]
    if out.type.suffixes and "fmt" in by and isinstance(by["fmt"].type, click.Choice):
        named = [x for x in (s.lstrip(".") for s in out.type.suffixes) if x in by["fmt"].type.choices]
        if named:                             # a device or FIFO has no suffix to name the format
            line.opts["fmt"] = (by["fmt"], named[0])
    if _invoke(line.argv(probe), check=True)[0]:
        for p in cmd.params:                  # an output some input goes with (sim zk -o needs --replay)
            if type(p.type).__name__ == "InputPath" and isinstance(p, click.Option) and p.type.holds in files:
                line.opts[p.name] = (p, files[p.type.holds])
                if _invoke(line.argv(probe), check=True)[0] == 0:
                    break
                del line.opts[p.name]
    return line


def _kinds_of_path(tmp_path, t):
    """The paths to try for an output of type ``t``: two devices, a FIFO, and a symlink to a
    0600 file (empty for a database; none yet for a state file: the link dangles)."""
    import os

    suffix = (t.suffixes or (".out",))[0]
    fifo = tmp_path / f"fifo{suffix}"
    os.mkfifo(fifo)
    target = tmp_path / f"target{suffix}"
    if t.kind != "state":
        target.write_bytes(b"" if t.kind == "database" else OLD)
        os.chmod(target, 0o600)
    link = tmp_path / f"link{suffix}"
    link.symlink_to(target)
    return {"/dev/null": "/dev/null", "/dev/full": "/dev/full", "fifo": str(fifo), "symlink": str(link)}, target


class _Drain:
    """Hold a FIFO open and read whatever is written to it, so a command that opens it opens
    at once (as with a reader at the other end) and never blocks the test."""

    def __init__(self, fifo):
        import os
        import threading

        self.fd = os.open(fifo, os.O_RDWR | os.O_NONBLOCK)
        self.got = b""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self):
        import os
        import select

        while not self._stop.is_set():
            if select.select([self.fd], [], [], 0.05)[0]:
                try:
                    self.got += os.read(self.fd, 65536)
                except BlockingIOError:
                    pass

    def close(self):
        import os

        self._stop.set()
        self._thread.join(2)
        os.close(self.fd)


@pytest.mark.parametrize("where", ["/dev/null", "/dev/full", "fifo", "symlink"])
@pytest.mark.parametrize("path,name", OUTPUTS, ids=[f"{' '.join(p)} {n}" for p, n in OUTPUTS])
def test_an_output_option_survives_devices_fifos_and_symlinks(path, name, where, files, port, tmp_path):
    import os
    import stat

    cmd = dict(commands())[tuple(path)]
    param = next(p for p in cmd.params if p.name == name)
    line = _runnable(path, cmd, name, files, port)
    paths, real = _kinds_of_path(tmp_path, param.type)
    target = paths[where]
    before = real.read_bytes() if real.exists() else None
    if "listen" in {p.name for p in cmd.params}:
        line.opts["listen"] = (next(p for p in cmd.params if p.name == "listen"), "127.0.0.1:0")
    argv = line.argv((param, target))
    drain = _Drain(target) if where == "fifo" else None
    try:
        code = _serve_briefly(argv) if "listen" in line.opts else _invoke(argv, check=False)[0]
    finally:
        if drain is not None:
            drain.close()
    # a database, a state file and a symlink need a file of their own: a device or FIFO is refused
    needs_file = param.type.kind in ("database", "state", "link")
    # a command that only listens (taps, no port of its own) hears nothing on a simulated bus
    # nobody talks on, and ends as a silent line ends (exit 3): its files must be intact all the same
    ran = (0, 3) if "ports" in {p.name for p in cmd.params} and "zap" in path else (0,)
    if where.startswith("/dev/"):
        assert stat.S_ISCHR(os.stat(target).st_mode), f"{' '.join(argv)} replaced {target}"
        allowed = (2,) if needs_file else {"/dev/null": ran, "/dev/full": (*ran, 7)}[where]
        assert code in allowed, f"{' '.join(argv)}: exit {code}"
    elif where == "fifo":
        assert stat.S_ISFIFO(os.stat(target).st_mode), f"{' '.join(argv)} replaced the FIFO"
        assert code in ((2,) if needs_file else ran), f"{' '.join(argv)}: exit {code}"
    else:
        assert os.path.islink(target), f"{' '.join(argv)} replaced the symlink"
        assert code in ((2,) if param.type.kind == "link" else ran), f"{' '.join(argv)}: exit {code}"
        if before is not None and real.read_bytes() != before:   # written through the link (if a record came)
            assert stat.S_IMODE(os.stat(real).st_mode) == 0o600, f"{' '.join(argv)}: the mode changed"


#: What no output can be: refused before anything runs (exit 2, nothing sent), where writing
#: telemetry to a kernel interface file failed as "disk full" (exit 7).
UNWRITABLE = ["symlink-loop", "socket", "proc", "proc-new", "sys"]


@pytest.fixture(scope="module")
def special(tmp_path_factory):
    import os
    import socket

    d = tmp_path_factory.mktemp("special")
    os.symlink(d / "loop-b", d / "loop-a")
    os.symlink(d / "loop-a", d / "loop-b")
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(d / "sock"))
    yield {"symlink-loop": str(d / "loop-a"), "socket": str(d / "sock"), "proc": "/proc/self/comm",
           "proc-new": "/proc/zkzap-output", "sys": "/sys/kernel/zkzap-output"}
    sock.close()


@pytest.mark.skipif(not __import__("os").path.ismount("/proc"), reason="no /proc")
@pytest.mark.parametrize("where", UNWRITABLE)
@pytest.mark.parametrize("path,name", OUTPUTS, ids=[f"{' '.join(p)} {n}" for p, n in OUTPUTS])
def test_an_output_that_no_file_can_be_is_refused(path, name, where, files, port, special):
    import os

    if where == "sys" and not os.path.ismount("/sys"):
        pytest.skip("no /sys")
    cmd = dict(commands())[tuple(path)]
    param = next(p for p in cmd.params if p.name == name)
    line = _runnable(path, cmd, name, files, port)
    if "listen" in {p.name for p in cmd.params}:
        line.opts["listen"] = (next(p for p in cmd.params if p.name == "listen"), "127.0.0.1:0")
    argv = line.argv((param, special[where]))
    sent = port.data
    code, out, err = _invoke(argv, check=False)
    assert code == 2, f"{' '.join(argv)}: exit {code}: {err}"
    assert "Traceback" not in err and err.count("\n") <= 2, err
    assert not os.path.exists("/proc/zkzap-output") and not os.path.exists("/sys/kernel/zkzap-output")
    assert port.data == sent, f"{' '.join(argv)} sent to the port"


# --- every input file can be a named pipe or a process substitution -------------------------

def _inputs():
    """(command path, input parameter name): one per command group and what the input holds
    (the sub-commands of a group share their options' code), but a database (SQLite reads a
    file of its own)."""
    seen, out = set(), []
    for path, cmd in commands():
        if "listen" in {p.name for p in cmd.params} or path[0] == "sim":
            continue                          # a server runs until stopped
        for p in _params(cmd):
            if type(p.type).__name__ != "InputPath" or p.type.holds in ("logbook",):
                continue
            key = (path[:-1], p.type.holds, isinstance(p, click.Option))
            if key not in seen:
                seen.add(key)
                out.append((path, p.name))
    return out


INPUTS = _inputs()


def test_the_input_walk_finds_every_kind():
    kinds = {(" ".join(p), n) for p, n in INPUTS}
    for expected in [("zk decode", "inputs"), ("zk report", "run_files"), ("zk monitor", "replay"),
                     ("zk profile", "schedule")]:
        assert expected in kinds, sorted(kinds)


def _feed(fifo, data):
    """A writer that opens the FIFO (waiting for its reader), writes ``data`` and closes it."""
    import threading

    def write():
        try:
            with open(fifo, "wb") as f:
                f.write(data)
        except OSError:
            pass

    thread = threading.Thread(target=write, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize("path,name", INPUTS, ids=[f"{' '.join(p)} {n}" for p, n in INPUTS])
def test_an_input_that_is_a_fifo_reads_as_its_file(path, name, files, port, tmp_path):
    import os

    cmd = dict(commands())[tuple(path)]
    param = next(p for p in cmd.params if p.name == name)
    line = Line(path, cmd)
    base = _valid_line(path, cmd, files, port)
    line.args = dict(base.args)
    line.opts = {k: v for k, v in base.opts.items() if type(v[0].type).__name__ != "OutputPath"}
    by = {p.name: p for p in cmd.params}
    for pname in ("port", "ports"):
        if pname in line.opts:
            if name == "replay":
                del line.opts[pname]          # a replay is the port
            else:
                line.opts[pname] = (by[pname], _sim_for(path))
    # (a run bounded by time gets 1.5 s: the file's run and the FIFO's must both see their
    # frames, also on a loaded machine; --count ends most of them sooner)
    for pname, value in [("count", "3"), ("for_s", "1.5"), ("duration", "1.5"), ("fast", True), ("dry_run", True),
                         ("terminal", True)]:
        if pname in by and pname not in line.opts:
            line.opts[pname] = (by[pname], value)
            if _invoke(line.argv(), check=True)[0]:
                del line.opts[pname]
    source = files[param.type.holds]
    with open(source, "rb") as f:
        data = f.read()
    argv = line.argv((param, source))
    code, out, err = _invoke(argv, check=False)
    fifo = tmp_path / ("in" + os.path.splitext(source)[1])
    os.mkfifo(fifo)
    writer = _feed(fifo, data)
    fargv = line.argv((param, str(fifo)))
    fcode, fout, ferr = _invoke(fargv, check=False)
    writer.join(10 if code == 0 else 0.5)
    if writer.is_alive():
        os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))     # let the writer go
    assert code != 0 or not writer.is_alive(), f"{' '.join(fargv)}: never read the FIFO"
    assert fcode == code, f"{' '.join(fargv)}: exit {fcode} (the file: {code}): {ferr}"
    assert bool(fout) == bool(out), (out, fout)


def _serve_briefly(argv):
    """Run a serving command (a simulator) as a process until it says where it serves, then
    stop it with SIGTERM; its exit status (2: refused before it served)."""
    import os
    import signal
    import subprocess
    import sys

    exe = os.path.join(os.path.dirname(sys.executable), "zkzap")
    p = subprocess.Popen([exe, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = p.stdout.readline()
    if first:
        p.send_signal(signal.SIGTERM)
    p.communicate(timeout=30)
    # stopped as asked: a simulator exits 0 on SIGTERM, another server with its SIGTERM status
    return 0 if p.returncode == 143 and first else p.returncode


line_base = _valid_line


@pytest.mark.parametrize("path,name", OUTPUTS, ids=[f"{' '.join(p)} {n}" for p, n in OUTPUTS])
def test_an_output_option_refuses_its_own_input(path, name, files, port):
    cmd = dict(commands())[tuple(path)]
    param = next(p for p in cmd.params if p.name == name)
    if param.type.kind == "state":
        pytest.skip("a state file is its own input by design: read and rewritten whole")
    line = _valid_line(path, cmd, files, port)
    inputs = [(p, v) for p, v in list(line.args.values()) + list(line.opts.values())
              if type(p.type).__name__ == "InputPath"]
    if not inputs:                            # an optional input given: the command then reads it
        inputs = [(p, files[p.type.holds]) for p in cmd.params if type(p.type).__name__ == "InputPath"
                  and p.type.holds in files][:1]
        for p, v in inputs:
            line = Line(path, cmd)
            line.args, line.opts = dict(line_base(path, cmd, files, port).args), \
                dict(line_base(path, cmd, files, port).opts)
            (line.args if isinstance(p, click.Argument) else line.opts)[p.name] = (p, v)
    if not inputs:
        pytest.skip(f"{' '.join(path)} reads no file")
    given, value = inputs[0]
    before = open(value, "rb").read()
    argv = line.argv((param, value))
    code, out, err = _invoke(argv, check=False)
    assert code == 2 and out == "", f"{' '.join(argv)}: exit {code}: {err}"
    # a symlink is never made over a file; anything else names the input it would destroy
    assert "is also the input" in err or param.type.kind == "link", err
    assert open(value, "rb").read() == before


_PORTED = [(path, name) for path, name in OUTPUTS
           if {"port", "ports"} & {p.name for p in dict(commands())[tuple(path)].params}]


@pytest.mark.parametrize("path,name", _PORTED, ids=[f"{' '.join(p)} {n}" for p, n in _PORTED])
def test_an_output_option_refuses_the_port_itself(path, name, files, port, tmp_path):
    """Records, a capture or a document written into the control line: refused (exit 2) before
    the port opens, whether the output names the port's device or a symlink to it."""
    import os
    import select

    cmd = dict(commands())[tuple(path)]
    param = next(p for p in cmd.params if p.name == name)
    by = {p.name: p for p in cmd.params}
    master, slave = os.openpty()
    try:
        device = os.ttyname(slave)
        link = tmp_path / "the-port"
        link.symlink_to(device)
        line = Line(path, cmd)
        base = _valid_line(path, cmd, files, port)
        line.args, line.opts = dict(base.args), dict(base.opts)
        pname = "port" if "port" in by else "ports"
        line.opts[pname] = (by[pname], device)
        for target in (device, str(link)):
            argv = line.argv((param, target))
            code, out, err = _invoke(argv, check=False)
            assert code == 2 and out == "", f"{' '.join(argv)}: exit {code}: {err}"
            assert "is the port" in err, err
        assert not select.select([master], [], [], 0)[0], "bytes went onto the line"
    finally:
        os.close(master)
        os.close(slave)


def test_stdout_that_is_the_port_is_refused(tmp_path):
    """``zk send ... -p /dev/ttyUSB0 > /dev/ttyUSB0``: stdout is the control line."""
    import os
    import subprocess
    import sys

    master, slave = os.openpty()
    try:
        exe = os.path.join(os.path.dirname(sys.executable), "zk")
        r = subprocess.run([exe, "send", "control", "--state", "run", "--throttle", "20", "--for", "1", "--yes",
                            "-p", os.ttyname(slave)], stdout=slave, stderr=subprocess.PIPE, text=True, timeout=60)
        assert r.returncode == 2 and "stdout is the port" in r.stderr, r.stderr
    finally:
        os.close(master)
        os.close(slave)


# --- a command that writes names its actuator ---------------------------------------------------

#: Commands with an actuator ID option (``-i/--id``), found by walking the tree.
ID_COMMANDS = [path for path, cmd in commands() if any(p.name == "ident" for p in cmd.params)]
#: Writes the detection below must find (it would otherwise pass by finding none).
KNOWN_WRITERS = {("zap", "store"), ("zap", "move"), ("zap", "factory-reset")}


def _acting(packet: bytes) -> bool:
    """Whether a command packet writes to or acts on an actuator: anything but Echo and Load Data."""
    from zkzap.codec import zap

    return len(packet) > 5 and packet[5] not in (zap.ECHO, zap.LOAD_DATA)


@pytest.mark.parametrize("path", ID_COMMANDS, ids=" ".join)
def test_a_command_that_writes_has_no_default_id(path, files, port):
    """Run on a simulator (its ground truth: what the actuator heard) with ``--id``, a command
    that wrote to or acted on the actuator has no default ID: without ``--id`` it is bad usage
    (exit 2, nothing on stdout, the port never reached), in a batch's check too."""
    from zkzap.sim import start_zap

    cmd = dict(commands())[tuple(path)]
    by = {p.name: p for p in cmd.params}
    ident = by["ident"]
    base = _valid_line(path, cmd, files, port)
    line = Line(path, cmd)
    line.args = dict(base.args)
    line.opts = {k: v for k, v in base.opts.items()                     # no output: the walk's files stay
                 if type(v[0].type).__name__ != "OutputPath"}
    for p in cmd.params:                     # an instruction that acts (the walk's example reads)
        if type(p.type).__name__ == "InstructionType":
            line.args[p.name] = (p, "restart")
    line.opts["ident"] = (ident, "2")        # another ID than the examples' 1 (set-id's NEW)
    with start_zap(ids=[2], virtual=True) as sim:
        truth = sim.device.record_truth()
        line.opts["port"] = (by["port"], sim.url)
        code, out, err = _invoke(line.argv(), check=False)
        assert "Traceback" not in err, err
        wrote = [h.packet.hex(" ") for h in truth if _acting(h.packet)]
    if tuple(path) in KNOWN_WRITERS:
        assert wrote, f"{' '.join(line.argv())}: no write seen (exit {code}: {err})"
    no_default = ident.required or ident.default is None
    if wrote:
        assert no_default, f"{' '.join(path)} writes ({wrote[0]}) but --id defaults to {ident.default!r}"
    if not no_default:
        return
    del line.opts["ident"]
    line.opts["port"] = (by["port"], port.url)
    before = port.seen()
    for check in (True, False):
        code, out, err = _invoke(line.argv(), check=check)
        assert code == 2 and out == "", f"{' '.join(line.argv())} (check={check}): exit {code}: {out!r} {err}"
        assert "--id" in err and "Traceback" not in err, err
    assert port.seen() == before, f"{' '.join(line.argv())}: the port was reached"


@pytest.mark.parametrize("argv,code", [
    (["zap", "move", "100", "--id", "broadcast"], 0),                          # given: a broadcast goes out
    (["zap", "store", "goal-speed", "500", "--id", "broadcast"], 0),
    (["zap", "factory-reset", "--id", "broadcast", "--yes"], 2),             # its rules: --force too
    (["zap", "factory-reset", "--id", "broadcast", "--yes", "--force"], 0),
])
def test_broadcast_is_given_explicitly_under_its_rules(argv, code):
    from zkzap.sim import start_zap

    with start_zap(ids=[1, 2], virtual=True) as sim:
        truth = sim.device.record_truth()
        got, out, err = _invoke([*argv, "-p", sim.url], check=False)
        assert got == code, err
        heard = [h for h in truth if _acting(h.packet)]
        assert (len(heard) == 2) == (code == 0), heard           # both actuators heard it, or neither


def test_a_port_that_may_be_given_again_takes_one_port_from_a_default_or_the_environment(monkeypatch):
    """A batch's or shell's port reaches every line's command as one value, whether that command
    takes one bus or several (-p again); the environment's port is one port, spaces and all."""
    several = [(path, p) for path, cmd in commands() for p in cmd.params
               if isinstance(p, click.Option) and p.name == "port" and p.multiple]
    assert len(several) >= 4, several                     # scan, watch, play, cycle at least
    for path, p in several:
        ctx = click.Context(click.Command(path[-1]))
        assert p.type_cast_value(ctx, "sim://zap?ids=1") == ("sim://zap?ids=1",), path
        assert p.type_cast_value(ctx, ("a", "b")) == ("a", "b"), path
        for env in p.envvar if isinstance(p.envvar, (list, tuple)) else [p.envvar]:
            monkeypatch.setenv(env, "/dev/serial/by-id/usb-FTDI adapter-if00")
            assert p.type_cast_value(ctx, p.value_from_envvar(ctx)) == ("/dev/serial/by-id/usb-FTDI adapter-if00",)
