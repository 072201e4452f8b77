"""Output by format (writers), byte sources, and the terminal helpers that decide colour and tables."""

#: Output formats; :mod:`.writers` implements them. Kept here so option parsing imports no writer.
FORMATS = ("table", "json", "jsonl", "csv")
