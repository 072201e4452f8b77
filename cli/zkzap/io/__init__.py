"""Output by format (writers), byte sources, and the terminal helpers that decide colour and tables."""

#: Output formats; :mod:`.writers` implements them. Kept here so option parsing imports no writer.
FORMATS = ("table", "json", "jsonl", "csv")
#: Formats of the record streams (decode, monitor): the tables' formats and InfluxDB line protocol.
RECORD_FORMATS = FORMATS + ("influx",)
#: Formats of a logging session (monitor, send --for, profile): also MCAP files.
LOG_FORMATS = RECORD_FORMATS + ("mcap",)
#: Formats of a logging session's ``-o`` that also carry the steps and the summary (a workbook).
SESSION_FORMATS = LOG_FORMATS + ("xlsx",)
#: Columnar files a session's ``-o`` also writes (:mod:`.columnar`): Apache Parquet, ASAM MDF 4.
COLUMNAR_FORMATS = ("parquet", "mf4")
SESSION_FORMATS += COLUMNAR_FORMATS

#: File-name suffix -> format: what ``-o FILE`` names when ``-f`` is not given. Each command
#: takes the suffixes of its own formats; a suffix not known here (or not one of the command's
#: formats) is refused rather than guessed.
SUFFIXES = {
    ".csv": "csv", ".json": "json", ".jsonl": "jsonl", ".ndjson": "jsonl", ".lp": "influx", ".mcap": "mcap",
    ".xlsx": "xlsx", ".parquet": "parquet", ".mf4": "mf4", ".toml": "toml", ".yaml": "yaml", ".yml": "yaml", ".png": "png", ".svg": "svg",
    ".pdf": "pdf", ".html": "html", ".htm": "html",
}


def format_for_path(path, formats, default="jsonl", what="output"):
    """The format ``path``'s suffix names among ``formats``; ``default`` for a name without a
    suffix (None: refused too). An unknown suffix, or one of a format the command does not
    write, is a UsageError (exit 2) naming the suffixes it does take."""
    import os

    from ..errors import UsageError

    ext = os.path.splitext(os.path.basename(str(path)))[1].lower()
    if not ext and default is not None:
        return default
    fmt = SUFFIXES.get(ext)
    if fmt is not None and fmt in formats:
        return fmt
    known = ", ".join(s for s, f in SUFFIXES.items() if f in formats)
    said = f"the suffix {ext!r}" if ext else "a name without a suffix"
    if fmt is not None:
        said += f" ({fmt})"
    raise UsageError(f"{what}: {path}: {said} is not a format this command writes; name the file {known}, "
                     f"or give -f FORMAT")
