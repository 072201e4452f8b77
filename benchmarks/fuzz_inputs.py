"""Fuzz every kind of input zkzap reads, through the commands and API calls that read it.

    python benchmarks/fuzz.py inputs                          # 3000 cases per kind, seed 1
    python benchmarks/fuzz.py inputs --cases 200 --kind schedule --kind capture-zk --jobs 2

Each kind starts from valid files that zkzap itself wrote in a short session against its
simulators (a fleet backup as JSON, TOML and YAML, a setup state, a simulator state, the shipped
schedules and limits, zap and zk batches, ZK and mightyZAP pcapng captures, raw logs, hex dumps
as xxd, hexdump -C, plain hex and a logic analyser's CSV, a profile run's telemetry as CSV,
JSON Lines and JSON with its steps and summary, a logbook) and mutates them: bit flips, bytes
replaced, ranges deleted, duplicated (a key or a block given twice) or cut off, lines swapped,
and tokens spliced in — integers of 5000 digits, 1e308, NaN, deep nesting, byte order marks,
invalid UTF-8, NUL, lines of 200 000 characters, YAML anchors and tags, and, in binary files,
4-byte fields overwritten with lying lengths (0, 8, 0xFFFFFFFF, ...).

Every case runs in a worker process (a pool of ``--jobs``) under an address-space limit, with
a deadline: a worker that does not answer in ``--timeout`` seconds is killed and the case
reported as a hang. What counts as a finding:

- ``traceback``: an exception escaped (the command line would print a traceback);
- ``exit``: an exit status the kind does not allow (2 is bad input; 0/1/3/4/5 where documented);
- ``lines``: a refusal (exit 2) that is not exactly one line on stderr;
- ``unnamed``: a refusal that does not name the input (its file name, or ``stdin``);
- ``stdout``: a refusal that wrote to stdout;
- ``hang``: no answer within the deadline;
- ``memory``: the worker's resident memory peaked more than ``--memory`` MiB above where the
  case started (the high-water mark is reset before each case).

The tally per kind (cases, outcomes by exit status, findings, the largest RSS growth of a case,
the most CPU time a case took) is printed at the end; the exit status is 1 when anything was
found.
"""

from __future__ import annotations

import multiprocessing
import os
import random
import shutil
import sys
import tempfile
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "cli"))

#: Memory the worker may map beyond what it has after start-up (RLIMIT_AS): a reader that
#: believes a length field dies here with MemoryError instead of swapping the machine.
ADDRESS_HEADROOM = 1 << 30
#: Cases a worker runs before it is replaced (a fresh interpreter bounds any slow leak).
WORKER_CASES = 400
NOT_A_PORT = "/nonexistent/zkzap-fuzz-port"


# --- seeds: valid inputs, written by zkzap itself -----------------------------------------------

def _cli(args, stdin=None):
    """Run ``zkzap ARGS`` in this process: (exit status, stdout bytes, stderr text)."""
    from click.testing import CliRunner

    from zkzap.commands import root, run

    with CliRunner().isolation(input=stdin) as streams:
        code = run(root, "zkzap", list(args))
        return code, streams[0].getvalue(), streams[1].getvalue().decode("utf-8", "replace")


def _xxd(data: bytes) -> bytes:
    out = []
    for off in range(0, len(data), 16):
        row = data[off:off + 16]
        groups = " ".join(row[i:i + 2].hex() for i in range(0, len(row), 2))
        text = "".join(chr(b) if 32 <= b < 127 else "." for b in row)
        out.append(f"{off:08x}: {groups:<39}  {text}")
    return ("\n".join(out) + "\n").encode()


def _hexdump_c(data: bytes) -> bytes:
    out = []
    for off in range(0, len(data), 16):
        row = data[off:off + 16]
        cells = " ".join(f"{b:02x}" for b in row[:8]) + "  " + " ".join(f"{b:02x}" for b in row[8:])
        text = "".join(chr(b) if 32 <= b < 127 else "." for b in row)
        out.append(f"{off:08x}  {cells:<48}  |{text}|")
    out.append(f"{len(data):08x}")
    return ("\n".join(out) + "\n").encode()


def _od(data: bytes) -> bytes:
    """``od -A x -t x1z``: offsets, bytes and the >printable< column."""
    out = []
    for off in range(0, len(data), 16):
        row = data[off:off + 16]
        text = "".join(chr(b) if 32 <= b < 127 else "." for b in row)
        out.append(f"{off:06x} " + " ".join(f"{b:02x}" for b in row).ljust(47) + f"  >{text}<")
    out.append(f"{len(data):06x}")
    return ("\n".join(out) + "\n").encode()


def _saleae(data: bytes) -> bytes:
    return ("Time [s],Value\n" + "".join(f"{i * 8.68e-5:.8f},0x{b:02X}\n" for i, b in enumerate(data))).encode()


def make_seeds(d: str) -> dict:
    """{seed name: bytes}: valid inputs of every kind, from short sessions on the simulators."""
    from zkzap.api import fleet
    from zkzap.commands.zk.profile import example_text
    from zkzap.sim.zap_actuators import from_options

    def path(name):
        return os.path.join(d, name)

    def read(name):
        with open(path(name), "rb") as f:
            return f.read()

    seeds = {}
    code, _, err = _cli(["zap", "backup", "--sim", "--sim-ids", "1,2", "--ids", "1,2", "-o", path("fleet.json")])
    assert code == 0, err
    doc = fleet.loads(read("fleet.json").decode(), "json", "fleet.json")
    for fmt in ("json", "toml", "yaml"):
        seeds[f"fleet.{fmt}"] = fleet.dumps(doc, fmt).encode()
    state = fleet.SetupState(path("setup.json"), [1, 2, 3])
    state.mark_done(1, {"from_id": 0, "from_baud": 57600, "baud": 57600, "writes": 1, "time": fleet.now_iso()})
    state.mark_skipped(2)
    seeds["setup.json"] = read("setup.json")
    from_options(ids="1,2", state=path("bus.json")).save()
    seeds["bus.json"] = read("bus.json")
    seeds["profile.csv"] = example_text("throttle").encode()
    seeds["rpm.csv"] = example_text("rpm").encode()
    seeds["engine.limits"] = example_text("limits").encode()
    seeds["zap-batch.txt"] = (b"# new actuators on the bench\nstore goal-speed 600 --id 1\nmove 2000 --id 1 --wait\n"
                              b"load present-voltage --id 1 --physical\necho --id 2 --count 3\n"
                              b"sync-move 1:1000 2:2000\nraw load 8C 02 --id 1\n")
    seeds["aux-pairs.txt"] = b"".join(f"thrust_n={i * 1.5:.1f} t_c=21.{i % 10} p_hpa=1013\n".encode() for i in range(40))
    seeds["aux.csv"] = b"thrust_n;flow_ml_min;name\n" + b"".join(f"{i}.5;{250 + i};cell\n".encode() for i in range(40))
    seeds["aux.jsonl"] = b"".join(f'{{"thrust_n": {i}.25, "rpm": {i}, "ok": true}}\n'.encode() for i in range(40))
    seeds["zk-batch.txt"] = (b"send keepalive\nsend control --state stop\nmonitor --count 20 --ids 1\n"
                             b"send action rate-50hz\nsend rpm 99990 --rpm-factor 3\n")
    # a ZK session: telemetry in every text format, its raw log and its capture
    sched = path("stand.csv")
    with open(sched, "w") as f:
        f.write("0,0,run\n4,40\n8,0,standby\n10,0,standby\n")
    code, _, err = _cli(["zk", "profile", sched, "-p", "sim://zk?speed=50", "-o", path("tel.csv"), "--raw-log",
                         path("raw.bin"), "--capture", path("zk.pcapng"), "--settle", "1", "--steps-csv",
                         path("steps.csv"), "--summary-json", path("summary.json"), "--logbook", path("lb.db"),
                         "--limit", "egt_c<=900"])
    assert code == 0, err
    for name in ("tel.csv", "raw.bin", "zk.pcapng", "steps.csv", "summary.json"):
        seeds[name] = read(name)
    for fmt in ("jsonl", "json"):
        code, _, err = _cli(["zk", "monitor", "--replay", path("raw.bin"), "--fast", "-f", fmt, "-o",
                             path(f"tel.{fmt}")])
        assert code == 0, err
        seeds[f"tel.{fmt}"] = read(f"tel.{fmt}")
    import sqlite3

    db = sqlite3.connect(path("lb.db"))
    db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    db.execute("PRAGMA journal_mode = DELETE")
    db.close()
    seeds["lb.db"] = read("lb.db")
    # a mightyZAP session over a capture (both directions), and its bytes as a raw stream
    with open(path("zap-lines.txt"), "w") as f:
        f.write("echo --id 1\nload present-position --id 1\nstore goal-speed 600 --id 1\nload goal-speed --id 2\n"
                "dump --id 2\n")
    code, _, err = _cli(["zap", "batch", path("zap-lines.txt"), "--sim", "--sim-ids", "1,2", "--capture",
                         path("zap.pcapng")])
    assert code == 0, err
    seeds["zap.pcapng"] = read("zap.pcapng")
    from zkzap.link.pcapng import Reader

    seeds["zap.bin"] = b"".join(k.data for k in Reader(path("zap.pcapng")))
    zk_bytes = seeds["raw.bin"][:700] + b"".join(k.data for k in Reader(path("zk.pcapng")) if k.direction == 2)[:80]
    seeds["zk.hex"] = (" ".join(f"{b:02X}" for b in zk_bytes[:300]) + "\n").encode()
    seeds["zk.xxd"] = _xxd(zk_bytes)
    seeds["zk.hexdump"] = _hexdump_c(zk_bytes)
    seeds["zk.saleae.csv"] = _saleae(zk_bytes[:200])
    seeds["zk.od"] = _od(zk_bytes)
    seeds["zap.xxd"] = _xxd(seeds["zap.bin"][:600])
    return seeds


# --- the kinds: which seeds, how a case is run, which exit statuses are allowed ------------------

#: CPU seconds a case of a kind may take by default (the inputs are at most a few hundred KiB).
CPU_S = 2.0


class Kind:
    """An input kind: its seeds, the file name a case is written to, and ``run(path, data)``
    returning (exit status, stdout bytes, stderr text). ``named``: a refusal must name the
    input (its file name, or ``stdin`` for standard input). ``cpu``: the CPU seconds a case may
    take before it is a finding (a reader that is quadratic in some input)."""

    def __init__(self, name, seeds, filename, run, allowed=(0, 2), binary=False, named=True, weight=1.0,
                 needs=None, warm=True, cpu=CPU_S):
        self.name, self.seeds, self.filename, self.run, self.cpu = name, seeds, filename, run, cpu
        self.allowed, self.binary, self.named, self.weight, self.needs = set(allowed), binary, named, weight, needs
        #: run once on a seed when a worker starts, so the modules it imports are not counted as
        #: a case's memory
        self.warm = warm


def _api(call, refusals=()):
    """An API reader as a kind's run: a UsageError (and ``refusals``) is a refusal, exit 2."""
    from zkzap.errors import UsageError

    def run(path, data):
        try:
            call(path)
        except (UsageError, *refusals) as e:
            return 2, b"", f"error: {e}\n"
        return 0, b"", ""
    return run


def _sim_zk_replay(path):
    from zkzap.link.pcapng import check_capture
    from zkzap.sim.replay import ZkReplay

    check_capture(path, "zk")
    try:
        r = ZkReplay(path)
    except ValueError as e:
        if "no status frame" in str(e):
            return
        raise
    try:
        r.poll(1e12)
    finally:
        r.close()


def _sim_zap_replay(path):
    from zkzap.link.pcapng import check_capture
    from zkzap.sim.replay import recorded_replies

    check_capture(path, "zap")
    recorded_replies(path)


def _aux_lines(path):
    from zkzap.api.aux import MAX_LINE, LineParser

    parser = LineParser(frozenset({"rpm", "t"}))
    with open(path, "rb") as f:
        for line in iter(lambda: f.readline(MAX_LINE), b""):       # as the reader thread cuts them
            parser.feed(line.decode("utf-8", "replace"))
    parser.fields()


def _setup_state(path):
    from zkzap.api.fleet import SetupState

    SetupState.load(path, [1, 2, 3]).pending()


def _sim_state(path):
    from zkzap.sim.zap_actuators import from_options

    from_options(state=path)


def kinds(seeds: dict, d: str) -> list:
    """Every input kind, with its runner."""
    def cli(*args, stdin=False):
        def run(path, data):
            argv = [a.replace("{}", path) for a in args]
            return _cli(argv, stdin=data if stdin else None)
        return run

    fleet_ref = os.path.join(d, "fleet.json")
    with open(fleet_ref, "wb") as f:
        f.write(seeds["fleet.json"])
    raw = os.path.join(d, "raw.bin")
    steps, summary = os.path.join(d, "steps.csv"), os.path.join(d, "summary.json")

    def report(which):
        def run(path, data):
            files = {"run": os.path.join(d, "tel.csv"), "steps": steps, "summary": summary, which: path}
            return _cli(["zk", "report", files["run"], "--steps", files["steps"], "--summary", files["summary"],
                         "--terminal"])
        return run

    def report_svg(path, data):
        return _cli(["zk", "report", path, "--steps", steps, "--summary", summary, "-o",
                     os.path.join(os.path.dirname(path), "report.svg")])

    k = [
        Kind("fleet-json", ["fleet.json"], "fleet.json", cli("zap", "diff", "{}", fleet_ref), (0, 1, 2)),
        Kind("fleet-toml", ["fleet.toml"], "fleet.toml", cli("zap", "diff", "{}", fleet_ref), (0, 1, 2)),
        Kind("fleet-yaml", ["fleet.yaml"], "fleet.yaml", cli("zap", "diff", "{}", fleet_ref), (0, 1, 2), needs="yaml"),
        Kind("fleet-stdin", ["fleet.json"], "-", cli("zap", "diff", "-", fleet_ref, stdin=True), (0, 1, 2)),
        Kind("setup-state", ["setup.json"], "setup.json", _api(_setup_state)),
        # the lines an --aux sensor sends (a reader thread parses them; a refusal names the source there)
        Kind("aux-lines", ["aux-pairs.txt", "aux.csv", "aux.jsonl"], "aux.txt", _api(_aux_lines), named=False),
        Kind("sim-state", ["bus.json"], "bus.json", _api(_sim_state, (ValueError,))),   # the simulator's refusal
        Kind("schedule", ["profile.csv", "rpm.csv"], "stand.csv", cli("zk", "profile", "{}", "-n")),
        Kind("limits", ["engine.limits"], "engine.limits",
             cli("zk", "monitor", "--replay", raw, "--fast", "--limits", "{}", "--on-limit", "warn"), (0, 2)),
        # every line is checked before the port opens: 2 for a bad line, else 4 (no such port), or 0
        # for a batch without a command
        Kind("zap-batch", ["zap-batch.txt"], "batch.txt", cli("zap", "batch", "{}", "-p", NOT_A_PORT), (0, 2, 4)),
        Kind("zk-batch", ["zk-batch.txt"], "batch.txt", cli("zk", "batch", "{}", "-p", NOT_A_PORT), (0, 2, 4)),
        Kind("capture-zk", ["zk.pcapng"], "c.pcapng", cli("zk", "decode", "{}", "-f", "jsonl"), binary=True),
        Kind("capture-zk-csv", ["zk.pcapng"], "c.pcapng", cli("zk", "decode", "{}", "-f", "csv"), binary=True),
        Kind("capture-zap", ["zap.pcapng"], "c.pcapng", cli("zap", "decode", "{}", "-f", "jsonl"), binary=True),
        Kind("replay-capture", ["zk.pcapng"], "c.pcapng", cli("zk", "monitor", "--replay", "{}", "--fast"),
             (0, 2, 3), binary=True),
        Kind("sim-replay-zk", ["zk.pcapng"], "c.pcapng", _api(_sim_zk_replay), binary=True),
        Kind("sim-replay-zap", ["zap.pcapng"], "c.pcapng", _api(_sim_zap_replay), binary=True),
        Kind("raw-log-replay", ["raw.bin"], "raw.bin", cli("zk", "monitor", "--replay", "{}", "--fast", "-f", "csv"),
             (0, 2, 3), binary=True),
        Kind("raw-zk-decode", ["raw.bin"], "raw.bin", cli("zk", "decode", "--binary", "{}"), binary=True),
        Kind("raw-zap-decode", ["zap.bin"], "zap.bin", cli("zap", "decode", "--binary", "{}", "-f", "csv"),
             binary=True),
        Kind("hex-zk", ["zk.hex", "zk.xxd", "zk.hexdump", "zk.saleae.csv"], "-",
             cli("zk", "decode", "-", stdin=True)),
        Kind("hex-zap", ["zap.xxd"], "-", cli("zap", "decode", "-", stdin=True)),
        # hex text files as the decoders' arguments (zk decode dump.hex): the file's bytes as found
        Kind("hex-file-zk", ["zk.hex", "zk.xxd", "zk.od"], "dump.hex", cli("zk", "decode", "{}", "-f", "csv"),
             binary=True),
        Kind("hex-file-zap", ["zap.xxd"], "dump.hex", cli("zap", "decode", "{}", "-f", "csv"), binary=True),
        Kind("hex-crc", ["zk.hex"], "-", cli("crc", "zk", "-", stdin=True)),
        Kind("report-run", ["tel.csv", "tel.jsonl", "tel.json", "raw.bin"], "run.txt", report("run")),
        Kind("report-stdin", ["tel.csv", "tel.jsonl", "raw.bin"], "-", cli("zk", "report", "-", "--terminal", stdin=True)),
        Kind("report-steps", ["steps.csv"], "steps.csv", report("steps")),
        # runs compared: a good run and a damaged one
        Kind("report-runs", ["tel.csv", "tel.jsonl", "raw.bin"], "run.txt",
             cli("zk", "report", os.path.join(d, "tel.csv"), "{}", "--terminal")),
        Kind("report-summary", ["summary.json"], "summary.json", report("summary")),
        Kind("report-svg", ["tel.csv", "tel.json"], "run.txt", report_svg, weight=0.05, needs="matplotlib",
             cpu=30.0),
        Kind("logbook", ["lb.db"], "lb.db", cli("zk", "logbook", "{}"), binary=True),
    ]
    return [x for x in k if x.needs is None or _importable(x.needs)]


def _importable(module) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


# --- mutation -------------------------------------------------------------------------------

TEXT_TOKENS = [b"9" * 5000, b"1e308", b"-1e308", b"1e400", b"nan", b"NaN", b"inf", b"-Infinity", b"-0", b"0x",
               b"\xff", b"\xfe", b"\xc3", b"\xed\xa0\x80", b"\xef\xbb\xbf", b"\xff\xfe", b"\x00", b"\r\n", b"\r",
               b"\n\n\n", b",", b";", b"\t", b"#", b'"', b"'", b"\\", b"[" * 3000, b"{" * 3000, b"{\"a\":" * 600,
               b"- " * 400, b"x" * 200_000, b'"' + b"a" * 140_000 + b'"', b"=", b"---\n", b"&a ", b"*a", b"<<: *a",
               b"!!python/object/apply:os.system ['true']", b"{}", b"[]", b"null", b"true", b"~", b"1" * 25,
               b"--", b" --port /dev/null", b" --sim", b" --count 0", b" --for 0", b"\x1b[2J"]
LYING_INTS = [0, 1, 2, 3, 4, 7, 8, 11, 12, 16, 20, 28, 0x7F, 0x80, 0xFF, 0x100, 0xFFFF, 0x10000, 0x7FFFFFFF,
              0x80000000, 0xFFFFFFF0, 0xFFFFFFFC, 0xFFFFFFFF]
MAX_CASE = 2 << 20


def mutate(rng: random.Random, data: bytes, binary: bool) -> bytes:
    """One mutated copy of ``data`` (see the module's description)."""
    b = bytearray(data)
    for _ in range(rng.choice((1, 1, 1, 2, 2, 3, 5, 8))):
        if not b:
            b += rng.randbytes(rng.randint(1, 16))
            continue
        p = rng.randrange(len(b))
        r = rng.random()
        if r < 0.14:
            b[p] ^= 1 << rng.randrange(8)
        elif r < 0.22:
            b[p] = rng.randrange(256)
        elif r < 0.30:
            del b[p:p + rng.choice((1, 2, 4, 16, 64, 512))]
        elif r < 0.40:                                # a range given twice (a key, a row, a block)
            a = rng.randrange(len(b))
            piece = b[a:a + rng.choice((4, 12, 40, 200, 2000))]
            b[p:p] = piece
        elif r < 0.46:
            del b[p:]
        elif r < 0.60:
            b[p:p] = rng.choice(TEXT_TOKENS) if not binary or rng.random() < 0.3 else rng.randbytes(rng.randint(1, 8))
        elif r < 0.75 and binary:                     # a field overwritten with a lying length
            q = p - p % 4
            value = rng.choice(LYING_INTS)
            b[q:q + 4] = value.to_bytes(4, rng.choice(("little", "little", "big")))
        elif r < 0.85:                                # lines: swap, duplicate or drop one
            lines = bytes(b).split(b"\n")
            if len(lines) > 2:
                i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
                op = rng.random()
                if op < 0.4:
                    lines[i], lines[j] = lines[j], lines[i]
                elif op < 0.8:
                    lines.insert(i, lines[j])
                else:
                    del lines[i]
                b = bytearray(b"\n".join(lines))
        else:
            b[p:p] = rng.randbytes(rng.randint(1, 32))
    return bytes(b[:MAX_CASE])


def cases(kind: Kind, seeds: dict, rng: random.Random, count: int):
    for _ in range(count):
        seed = seeds[rng.choice(kind.seeds)]
        yield seed if rng.random() < 0.02 else mutate(rng, seed, kind.binary)


# --- workers: each case under a deadline and an address-space limit ----------------------------

def _maxrss_mib() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _status_mib(field):
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


class _Peak:
    """A case's peak memory: the resident set's high-water mark reset before the case (Linux's
    /proc/self/clear_refs), read after it, less the resident set before; elsewhere the growth
    of the process's peak (which only sees a case that beats every case before it)."""

    def start(self):
        self.rss = _status_mib("VmRSS")
        self.reset = False
        if self.rss is not None:
            try:
                with open("/proc/self/clear_refs", "w") as f:
                    f.write("5")
                self.reset = True
            except OSError:
                pass
        self.before = _maxrss_mib()

    def grew(self) -> float:
        if self.reset:
            hwm = _status_mib("VmHWM")
            if hwm is not None:
                return max(0.0, hwm - self.rss)
        return max(0.0, _maxrss_mib() - self.before)


def _vsize() -> int:
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        return 0


def _die_with_parent():
    """A worker ends with the fuzzer, however that ends (a deadline's kill, Ctrl-C): on Linux by
    the kernel; elsewhere a worker's next read finds the pipe closed."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)      # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _worker(conn, parent_end, seeds, d, table):
    parent_end.close()               # forked with it: without this, a dead fuzzer's pipe never closes
    _die_with_parent()
    os.environ["NO_COLOR"] = "1"
    for var in [v for v in os.environ if v.startswith("ZKZAP_")]:
        del os.environ[var]
    work = tempfile.mkdtemp(prefix="case-", dir=d)
    os.chdir(work)
    table = {k.name: k for k in table}
    for k in table.values():                          # warm every path up before measuring anything
        if not k.warm:
            continue
        try:
            _write_and_run(k, work, seeds[k.seeds[0]])
        except Exception:  # noqa: BLE001 - a finding is reported when the case itself runs
            pass
    try:
        import resource

        vs = _vsize()
        if vs:
            resource.setrlimit(resource.RLIMIT_AS, (vs + ADDRESS_HEADROOM, vs + ADDRESS_HEADROOM))
    except (ImportError, ValueError, OSError):
        pass
    conn.send(("ready", _maxrss_mib()))
    while True:
        try:
            msg = conn.recv()
        except EOFError:             # the fuzzer is gone
            break
        if msg is None:
            break
        index, name, data = msg
        kind = table[name]
        peak = _Peak()
        peak.start()
        t0 = time.process_time()             # CPU time: a loaded machine does not make a case slow
        exc = None
        code, out, err = None, b"", ""
        try:
            code, out, err = _write_and_run(kind, work, data)
        except BaseException:  # noqa: BLE001 - what escapes is the finding
            exc = traceback.format_exc(limit=-8)
        err = err if len(err) <= 4000 else err[:2000] + err[-2000:]
        grew = peak.grew()
        conn.send((index, name, code, len(out), err, exc, time.process_time() - t0, grew, (peak.rss or 0.0) + grew))
        for f in os.listdir(work):
            p = os.path.join(work, f)
            if os.path.isdir(p):
                shutil.rmtree(p, ignore_errors=True)
            else:
                os.unlink(p)


def _write_and_run(kind, work, data):
    if kind.filename == "-":
        return kind.run("-", data)
    path = os.path.join(work, kind.filename)
    with open(path, "wb") as f:
        f.write(data)
    return kind.run(path, data)


# --- checking and the tally -------------------------------------------------------------------

class Finding:
    __slots__ = ("kind", "what", "detail", "data")

    def __init__(self, kind, what, detail, data):
        self.kind, self.what, self.detail, self.data = kind, what, detail, data


def judge(kind: Kind, result, data) -> list:
    """The findings of one case's result."""
    _index, _name, code, out_len, err, exc, cpu, grew, _rss = result
    found = []
    if cpu > kind.cpu:
        found.append(("cpu", f"{cpu:.1f} s of CPU time (more than {kind.cpu:g} s)"))
    if exc is not None:
        found.append(("traceback", exc.strip().splitlines()[-1] + "\n" + exc))
        return found
    if code not in kind.allowed:
        found.append(("exit", f"exit {code}: {err.strip()[-300:]}"))
    if code == 2:
        lines = [x for x in err.splitlines() if x.strip() and not x.startswith(("note:", "warning:"))]
        if len(lines) != 1:
            found.append(("lines", err[-600:]))
        elif kind.named:
            name = "stdin" if kind.filename == "-" else kind.filename
            if name not in lines[0] and os.path.splitext(name)[0] not in lines[0]:
                found.append(("unnamed", lines[0]))
        if out_len:
            found.append(("stdout", f"{out_len} bytes on stdout with: {err.strip()[-300:]}"))
    return found


class Tally:
    def __init__(self):
        self.cases = 0
        self.codes = {}
        self.findings = []
        self.max_grew = 0.0
        self.slowest = 0.0
        self.peak = 0.0

    def add(self, kind, result, data, found):
        self.cases += 1
        code = result[2]
        self.codes[code] = self.codes.get(code, 0) + 1
        self.max_grew = max(self.max_grew, result[7])
        self.slowest = max(self.slowest, result[6])
        self.peak = max(self.peak, result[8])
        for what, detail in found:
            self.findings.append(Finding(kind.name, what, detail, data))


def run(seed=1, count=3000, jobs=None, only=(), timeout=60.0, memory_mib=64.0, out=sys.stdout, keep=None,
        skip=(), extra=()):
    """Fuzz every kind (or ``only`` those named, less those in ``skip``; ``extra``: more
    :class:`Kind` objects) with ``count`` cases each; returns {kind: Tally}."""
    jobs = jobs or max(1, (os.cpu_count() or 1))
    d = tempfile.mkdtemp(prefix="zkzap-fuzz-")
    try:
        seeds = make_seeds(d)
        every = kinds(seeds, d) + list(extra)
        table = [k for k in every if (not only or k.name in only) and k.name not in skip]
        unknown = set(only) - {k.name for k in every}
        if unknown:
            raise SystemExit(f"unknown kind(s): {', '.join(sorted(unknown))}")
        def work():                     # made as they are handed out: the cases are never all in memory
            for k in table:
                krng = random.Random(f"{seed}:{k.name}")     # the same cases whichever kinds run
                for data in cases(k, seeds, krng, max(1, int(count * k.weight))):
                    yield k.name, data

        by_name = {k.name: k for k in table}
        tallies = {k.name: Tally() for k in table}
        _dispatch(work(), by_name, tallies, seeds, d, jobs, timeout, memory_mib)
        _report(tallies, out)
        if keep:
            _keep(tallies, keep)
        return tallies
    finally:
        shutil.rmtree(d, ignore_errors=True)


def _dispatch(work, by_name, tallies, seeds, d, jobs, timeout, memory_mib):
    ctx = multiprocessing.get_context("fork") if "fork" in multiprocessing.get_all_start_methods() \
        else multiprocessing.get_context()
    from multiprocessing.connection import wait

    class W:
        def __init__(self):
            self.conn, child = ctx.Pipe()
            # forked: the kinds (closures) are inherited, not pickled
            self.proc = ctx.Process(target=_worker, args=(child, self.conn, seeds, d, list(by_name.values())),
                                    daemon=True)
            self.proc.start()
            child.close()
            msg = self.conn.recv()
            assert msg[0] == "ready", msg
            self.case = None
            self.deadline = None
            self.done = 0

        def give(self, case):
            self.case = case
            self.deadline = time.monotonic() + timeout
            self.conn.send((0, *case))

        def stop(self, kill=False):
            if kill:
                self.proc.kill()
            else:
                try:
                    self.conn.send(None)
                except OSError:
                    pass
            self.proc.join(10)
            self.conn.close()

    first = next(work, None)
    if first is None:
        return
    workers = [W() for _ in range(max(1, jobs))]
    pending = [first]
    for w in workers:
        case = pending.pop() if pending else next(work, None)
        if case is not None:
            w.give(case)
    while any(w.case is not None for w in workers):
        busy = [w for w in workers if w.case is not None]
        left = max(0.0, min(w.deadline for w in busy) - time.monotonic())
        ready = wait([w.conn for w in busy], timeout=left)
        for w in list(workers):
            if w.case is None:
                continue
            name, data = w.case
            kind = by_name[name]
            replace = False
            if w.conn in ready:
                try:
                    result = w.conn.recv()
                except EOFError:           # the worker died (a crash of the interpreter itself)
                    result = (0, name, None, 0, "", f"the worker died (exit {w.proc.exitcode})", 0.0, 0.0, 0.0)
                    replace = True
                found = judge(kind, result, data)
                if result[7] > memory_mib:
                    found.append(("memory", f"peak RSS grew {result[7]:.0f} MiB in one case"))
                    replace = True          # its peak no longer measures the next cases
                tallies[name].add(kind, result, data, found)
            elif time.monotonic() >= w.deadline:
                result = (0, name, None, 0, "", None, timeout, 0.0, 0.0)
                tallies[name].add(kind, result, data, [("hang", f"no answer within {timeout:g} s")])
                replace = True
            else:
                continue
            w.done += 1
            if replace or w.done >= WORKER_CASES:
                w.stop(kill=True)
                workers[workers.index(w)] = w = W()
            else:
                w.case = None
            case = next(work, None)
            if case is not None:
                w.give(case)
            else:
                w.case = None
    for w in workers:
        w.stop()


def _report(tallies, out):
    total = sum(t.cases for t in tallies.values())
    bad = sum(len(t.findings) for t in tallies.values())
    print(f"inputs: {total} cases over {len(tallies)} kinds; {bad} findings", file=out)
    print(f"  {'kind':<16} {'cases':>6}  {'exit statuses':<34} {'findings':>8} {'max RSS +MiB':>12} "
          f"{'max CPU s':>9}", file=out)
    for name, t in tallies.items():
        codes = ", ".join(f"{c}: {n}" for c, n in sorted(t.codes.items(), key=lambda kv: (kv[0] is None, kv[0] or 0)))
        print(f"  {name:<16} {t.cases:>6}  {codes:<34} {len(t.findings):>8} {t.max_grew:>12.1f} {t.slowest:>9.2f}",
              file=out)
    peak = max((t.peak for t in tallies.values()), default=0.0)
    print(f"  peak resident memory of a worker during a case: {peak:.0f} MiB", file=out)
    shown = {}
    for t in tallies.values():
        for f in t.findings:
            key = (f.kind, f.what, _signature(f))
            if key in shown:
                continue
            shown[key] = f
            print(f"  {f.kind}: {f.what}: {_short_detail(f)}\n    input ({len(f.data)} bytes): {f.data[:160]!r}",
                  file=out)
            if len(shown) >= 40:
                return


def _signature(f):
    """What makes two findings the same: a traceback's exception and innermost zkzap frame, else
    the message without its numbers."""
    import re

    if f.what == "traceback":
        frames = re.findall(r'File "([^"]*zkzap[^"]*)", line (\d+)', f.detail)
        where = f"{os.path.basename(frames[-1][0])}:{frames[-1][1]}" if frames else ""
        return f.detail.splitlines()[0].split(":")[0] + " " + where
    return re.sub(r"\d+", "N", f.detail.splitlines()[0] if f.detail else "")[:100]


def _short_detail(f):
    if f.what != "traceback":
        return f.detail.strip()[:600]
    lines = f.detail.strip().splitlines()
    return lines[0] + "\n" + "\n".join("      " + x for x in lines[-14:])


def _keep(tallies, d):
    """Write every finding's input to ``d`` (for reproducing it)."""
    os.makedirs(d, exist_ok=True)
    for t in tallies.values():
        for i, f in enumerate(t.findings):
            with open(os.path.join(d, f"{f.kind}-{f.what}-{i}"), "wb") as fh:
                fh.write(f.data)


def main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(prog="fuzz.py inputs", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cases", type=int, default=3000, help="cases per kind (default 3000)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--kind", action="append", default=[], help="only this kind (repeatable)")
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds a case may take (default 60)")
    ap.add_argument("--memory", type=float, default=64.0, help="MiB of RSS growth a case may cause (default 64)")
    ap.add_argument("--keep", metavar="DIR", help="write the inputs of the findings to DIR")
    from common import add_quick

    add_quick(ap, cases=1, jobs=1)
    a = ap.parse_args(argv)
    tallies = run(a.seed, a.cases, a.jobs, a.kind, a.timeout, a.memory, keep=a.keep)
    return 1 if any(t.findings for t in tallies.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
