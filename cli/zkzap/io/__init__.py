"""Output by format (writers), byte sources, and the terminal helpers that decide colour and tables."""

#: Output formats; :mod:`.writers` implements them. Kept here so option parsing imports no writer.
FORMATS = ("table", "json", "jsonl", "csv")
#: Formats of the record streams (decode, monitor): the tables' formats and InfluxDB line protocol.
RECORD_FORMATS = FORMATS + ("influx",)
#: Formats of a logging session (monitor, send --for, profile): also MCAP files.
LOG_FORMATS = RECORD_FORMATS + ("mcap",)
