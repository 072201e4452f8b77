"""Test-stand options shared by ``zk monitor``, ``zk send --for``, ``zk profile`` and ``zk check``:
limits (``--limit``, ``--limits``, ``--on-limit``) and the engine logbook (``--logbook``).

The logic lives in :mod:`zkzap.api.limits`, :mod:`zkzap.api.logbook` and :mod:`zkzap.api.stand`;
this module turns options into a :class:`~zkzap.api.stand.Stand` (everything checked before a port
opens) and reports on it afterwards.
"""

from __future__ import annotations

import click

from ...errors import UsageError
from ..options import Choice, FilePath, FiniteRange, apply_options, note

LIMIT_HELP = ("Stop when a status field leaves a limit: FIELD OP NUMBER with OP one of < <= > >= == != "
              "and an optional warning band (egt_c<=850,warn=800; power_voltage_v>=7.2; error_code==0). "
              "Evaluated on every frame that carries the field. Repeatable.")


#: The finite float range every float option uses (one definition, in the options module).
Finite = FiniteRange


def limit_options(f):
    opts = [
        click.option("--limit", "limit", multiple=True, metavar="EXPR", help=LIMIT_HELP),
        click.option("--limits", "limits_files", multiple=True, type=FilePath(), metavar="FILE",
                     help="Read limits from FILE: one EXPR per line, '#' comments. Repeatable."),
        click.option("--on-limit", type=Choice(["abort", "exit", "warn"]), default=None,
                     help="On a violated limit: abort (the abort command, then exit 5; default when the "
                          "session controls the engine), exit (exit 5; the default otherwise) or warn "
                          "(go on; the summary names it)."),
    ]
    return apply_options(f, opts)


def logbook_option(f):
    return click.option("--logbook", type=FilePath(), default=None, metavar="FILE",
                        help="Record the run in the engine logbook FILE (SQLite; 'zk logbook FILE' lists "
                             "runs and totals).")(f)


def summary_option(f):
    return click.option("--summary-json", type=FilePath(), default=None, metavar="FILE",
                        help="Write the run's summary (frames, max rpm and EGT, fuel, states, errors, each "
                             "limit's verdict, extreme value and first violation) as JSON to FILE ('-': stdout).")(f)


def check_output_dir(path, what, records_to_stdout=False):
    """Refuse an output file whose directory is missing or read-only, before the run (and ``-``
    when the records already go to stdout)."""
    import os

    if path == "-" and records_to_stdout:
        raise UsageError(f"{what}: '-' needs -o FILE for the records (both would go to stdout)")
    if not path or path == "-":
        return
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        raise UsageError(f"{what}: cannot write {path}: no such directory")
    if not os.access(d, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise UsageError(f"{what}: cannot write {path}: permission denied")


def write_summary(path, *, command, port, outcome, tel, session, stand):
    """The run summary as JSON (``-``: stdout)."""
    import json

    from ...errors import OutputError

    out = {"command": command, "port": port, "outcome": outcome.reason, "exit_status": outcome.exit_code,
           "aborted": outcome.aborted, "duration_s": round(session.ended_t or 0.0, 3),
           "crc_errors": session.source.framer.bad}
    out.update(tel.summary())
    if stand is not None:
        out.update(stand.summary())
    text = json.dumps(out, ensure_ascii=False, indent=2) + "\n"
    if path == "-":
        click.echo(text, nl=False)
        return
    try:
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError as e:
        raise OutputError(f"summary-json: cannot write {path}: {e.strerror}") from None


def build_stand(*, limit=(), limits_files=(), on_limit=None, logbook=None, controls=False, averager=None,
                force=False):
    """A Stand for these options (None when none applies); raises UsageError (exit 2) first."""
    from ...api import limits as L
    from ...api.stand import Stand

    conditions = L.read_limits(limit, limits_files)
    if on_limit is not None and not conditions:
        raise UsageError("on-limit: give --limit EXPR or --limits FILE with it")
    if on_limit == "abort" and not controls:
        raise UsageError("on-limit: abort: this session does not control the engine; use exit or warn")
    if on_limit is None:
        on_limit = "abort" if controls else "exit"
    if logbook == "-":
        raise UsageError("logbook: a file is needed ('-' is not a database)")
    if logbook:
        from ...api import logbook as lb

        lb.check_writable(logbook)
    if not conditions and not logbook and averager is None and not force:
        return None
    return Stand(L.LimitSet(conditions, on_limit, notify=note) if conditions else None, averager, logbook)


def report(stand, *, command, port, schedule=None, files=(), outcome, tel, session, quiet=False, summary_json=None):
    """After a run: the limits summary on stderr, the logbook entry and the ``--summary-json`` file."""
    if summary_json:
        write_summary(summary_json, command=command, port=port, outcome=outcome, tel=tel, session=session,
                      stand=stand)
    if stand is None:
        return
    if stand.limits is not None and not quiet:
        from ...api.limits import summary_lines

        click.echo("limits:\n" + "\n".join(summary_lines(stand.limits.summary())), err=True)
    run_id = stand.log_run(command=command, port=port, schedule=schedule, files=files, outcome=outcome, tel=tel,
                           session=session)
    if run_id is not None:
        note(f"logbook {stand.logbook}: run {run_id} recorded")
