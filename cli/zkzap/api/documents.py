"""Structured documents from untrusted text: JSON, TOML and YAML, with one kind of error.

Fleet files (``zap backup``/``diff``/``apply``/``setup --config``), the state of a guided
setup, the simulator's state file and the summaries ``zk report`` reads are documents someone
may have edited, truncated or produced with another tool. Whatever the text holds, reading it
gives a value or a :class:`DocumentError` (a usage error, exit 2) of one line,
``FILE:LINE: what`` — never a traceback:

- a key given twice in one object is refused in every format (JSON parsers keep the last one
  silently; here it is an error, as TOML and YAML specify);
- nesting deeper than :data:`MAX_DEPTH` levels, an integer of more than :data:`MAX_DIGITS`
  digits and, in JSON, a number that is not finite (``NaN``, ``Infinity``, ``1e400``) are
  refused where they occur;
- JSON is read by the standard library, TOML by ``tomllib`` (``tomli`` on Python 3.10: the
  ``toml`` extra), YAML by PyYAML's safe loader (the ``yaml`` extra: ``pip install
  'zkzap[yaml]'``), with the file and line of its message kept.

The text itself comes from :func:`zkzap.api.textfile.read_text` (size bound, UTF-8, byte order
mark). Nothing here imports click or rich.
"""

from __future__ import annotations

import json
import math
import re

from ..errors import InvalidValue, MissingExtra, UsageError
from ..errors import clip as _clip

#: Deepest nesting of objects and lists read (zkzap's own documents need 4).
MAX_DEPTH = 100
#: Longest integer read, in digits (Python's own limit for converting text to int).
MAX_DIGITS = 4300
#: The largest YAML document read (bytes). PyYAML builds a node, its marks and its tokens for
#: every scalar before the value exists: about 100 bytes of memory and 5 us per character, so
#: YAML is held to 4 MiB (0.4 GB at most; a backup of 254 actuators is about 0.5 MB) where JSON
#: and TOML, read in a few bytes per character, take :data:`~zkzap.api.textfile.MAX_DOCUMENT`.
MAX_YAML = 4 << 20
#: Formats by file suffix.
SUFFIXES = {".json": "json", ".toml": "toml", ".yaml": "yaml", ".yml": "yaml"}


class DocumentError(UsageError):
    """A document that cannot be read or used; the message names the file (and the line or key)."""


def line_of(text: str, pos: int) -> int:
    """The line number (from 1) of character ``pos`` of ``text``."""
    return text.count("\n", 0, max(0, pos)) + 1


def loads(text: str, fmt: str, name: str = "document", *, finite: bool = True):
    """The value of ``text`` in ``fmt`` (``json``, ``toml``, ``yaml``); DocumentError naming
    ``name`` and the line. ``finite=False`` takes JSON's ``NaN`` and ``Infinity`` (as Python's
    own JSON writer puts them for float values)."""
    if fmt == "json":
        return load_json(text, name, finite=finite)
    if fmt == "toml":
        return load_toml(text, name)
    if fmt == "yaml":
        return load_yaml(text, name)
    raise InvalidValue(f"{name}: format {fmt!r}; allowed json, toml, yaml")


def read(path, what: str, fmt: str = "json", expected: str = "", limit=None, *, finite: bool = True):
    """``(value, name)`` of the document file ``path`` (``-``: stdin) in ``fmt``."""
    from .textfile import MAX_DOCUMENT, read_text

    text, name = read_text(path, what, expected, limit or (MAX_YAML if fmt == "yaml" else MAX_DOCUMENT))
    return loads(text, fmt, name, finite=finite), name


# --- JSON -------------------------------------------------------------------------------------

class _Refused(Exception):
    """Raised from inside the JSON parser's hooks: ``what`` at the literal ``text``."""

    def __init__(self, what, text=None):
        super().__init__(what)
        self.what, self.text = what, text


def _pairs(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise _Refused(f"key {k!r} is given twice", None)
        out[k] = v
    return out


def _int(text):
    if len(text) - (text[0] == "-") > MAX_DIGITS:
        raise _Refused(f"an integer of {len(text.lstrip('-'))} digits; at most {MAX_DIGITS}", text)
    return int(text)


def _float(text):
    value = float(text)
    if not math.isfinite(value):
        raise _Refused(f"{_clip(text)} is not a finite number", text)
    return value


def _constant(text):
    raise _Refused(f"{text} is not a finite number (JSON has no {text})", text)


_DECODER = json.JSONDecoder(object_pairs_hook=_pairs, parse_int=_int, parse_float=_float,
                            parse_constant=_constant)
_DECODER_NAN = json.JSONDecoder(object_pairs_hook=_pairs, parse_int=_int)

#: The characters that give JSON its structure: a string's opening quote, brackets, braces,
#: colons, commas.
_JSON_MARK = re.compile(r'[{}\[\]:,"]')


def load_json(text: str, name: str = "document", *, finite: bool = True):
    """The value of the JSON ``text`` (see the module's description; ``finite``: see
    :func:`loads`)."""
    try:
        return (_DECODER if finite else _DECODER_NAN).decode(text)
    except _Refused as e:
        refused = e.what, e.text
    except RecursionError:
        raise DocumentError(f"{name}:{line_of(text, _too_deep(_json_tokens(text)))}: nested more than "
                            f"{MAX_DEPTH} levels deep") from None
    except json.JSONDecodeError as e:
        raise DocumentError(f"{name}:{e.lineno}: not valid JSON: {e.msg} (column {e.colno})") from None
    except ValueError as e:           # a number the parser could not convert
        raise DocumentError(f"{name}: not valid JSON: {e}") from None
    # Located once the parser's frames (and the partial value they hold) are gone.
    what, literal = refused
    pos = _first_duplicate(text) if literal is None else text.find(literal)
    raise DocumentError(f"{name}:{line_of(text, pos)}: {what}")


def _json_tokens(text: str):
    """``(position, character, string)`` for every structural character of the (valid) JSON
    ``text``: a string's opening quote (with the string's value), a bracket, a brace, a colon or
    a comma. Strings are read by the standard library's scanner, so memory stays the size of
    the longest string, whatever the text (a regular expression for a whole string pushes
    state for every character: about 120 bytes each)."""
    from json.decoder import scanstring

    search, pos = _JSON_MARK.search, 0
    while True:
        m = search(text, pos)
        if m is None:
            return
        start, c = m.start(), m.group()
        if c == '"':
            try:
                value, pos = scanstring(text, start + 1)
            except ValueError:                    # a string not closed: the text ends here
                return
            yield start, c, value
        else:
            pos = start + 1
            yield start, c, None


def _first_duplicate(text: str) -> int:
    """Where the first key given twice in one object of the (valid) JSON ``text`` is, or -1."""
    stack, expect_key = [], False
    for pos, c, value in _json_tokens(text):
        if c == '"':
            if expect_key and stack and stack[-1] is not None:
                if value in stack[-1]:
                    return pos
                stack[-1].add(value)
            expect_key = False
        elif c == "{":
            stack.append(set())
            expect_key = True
        elif c == "[":
            stack.append(None)
            expect_key = False
        elif c in "}]":
            if stack:
                stack.pop()
            expect_key = False
        elif c == ",":
            expect_key = bool(stack) and stack[-1] is not None
        else:
            expect_key = False
    return -1


def _too_deep(tokens) -> int:
    """Where the nesting of the ``(position, character, ...)`` ``tokens`` first goes deeper
    than :data:`MAX_DEPTH`, or -1."""
    depth = 0
    for token in tokens:
        pos, c = token[0], token[1]
        if c in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                return pos
        elif c in "]}":
            depth -= 1
    return -1


def _lower(text: str) -> str:
    return text[:1].lower() + text[1:]


# --- TOML -------------------------------------------------------------------------------------

#: What opens a TOML string or comment, and TOML's brackets.
_TOML_MARK = re.compile(r'"""|\'\'\'|["\'#\[\]{}]')
#: The quote that closes a basic string: the first one after an even run of backslashes.
_TOML_QUOTE = re.compile(r'(?<!\\)\\*"')


def _toml_tokens(text: str):
    """``(position, bracket)`` for every bracket and brace of the TOML ``text`` outside its
    strings and comments, found with searches that keep no state per character."""
    search, pos = _TOML_MARK.search, 0
    while True:
        m = search(text, pos)
        if m is None:
            return
        start, tok = m.start(), m.group()
        if tok in ('"""', "'''", "'", "#"):
            end = text.find("\n" if tok == "#" else tok, m.end())
            pos = end + len(tok) if end >= 0 else len(text)
        elif tok == '"':
            pos = m.end()
            while True:
                q = _TOML_QUOTE.search(text, pos)
                if q is None:
                    return
                pos = q.end()
                if len(q.group()) % 2:            # an even run of backslashes before it: the end
                    break
        else:
            pos = m.end()
            yield start, tok


_TOML_WHERE = re.compile(r"\s*\(at line (\d+), column (\d+)\)$|\s*\(at end of document\)$")


def load_toml(text: str, name: str = "document"):
    """The value of the TOML ``text`` (see the module's description)."""
    try:
        import tomllib
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib
        except ImportError:
            raise MissingExtra(f"{name}: TOML on Python 3.10", "tomli", "toml") from None
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise DocumentError(f"{name}:{line_of(text, _too_deep(_toml_tokens(text)))}: nested more than "
                            f"{MAX_DEPTH} levels deep") from None
    except tomllib.TOMLDecodeError as e:
        msg = str(e)
        m = _TOML_WHERE.search(msg)
        if m is None:
            raise DocumentError(f"{name}: not valid TOML: {msg}") from None
        what = msg[:m.start()]
        if m.group(1):
            raise DocumentError(f"{name}:{m.group(1)}: not valid TOML: {_lower(what)} (column {m.group(2)})") \
                from None
        raise DocumentError(f"{name}:{line_of(text, len(text.rstrip()))}: not valid TOML: {_lower(what)} "
                            "(at the end)") from None
    except ValueError:                # an integer beyond Python's limit
        m = re.search(r"\d[\d_]{%d,}" % MAX_DIGITS, text)
        line = line_of(text, m.start()) if m else 1
        raise DocumentError(f"{name}:{line}: an integer of more than {MAX_DIGITS} digits") from None


# --- YAML -------------------------------------------------------------------------------------

_loader = None


def _yaml_loader(name):
    """PyYAML's safe loader, refusing duplicate keys, deep nesting and huge integers."""
    global _loader
    if _loader is not None:
        return _loader
    try:
        import yaml
    except ImportError:
        raise MissingExtra(f"{name}: YAML", "yaml (PyYAML)", "yaml") from None
    from yaml.composer import ComposerError
    from yaml.constructor import ConstructorError

    class Loader(yaml.SafeLoader):
        _depth = 0

        def compose_node(self, parent, index):
            self._depth += 1
            try:
                if self._depth > MAX_DEPTH:
                    raise ComposerError(None, None, f"nested more than {MAX_DEPTH} levels deep",
                                        self.peek_event().start_mark)
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

        def construct_mapping(self, node, deep=False):
            seen = set()
            if isinstance(node, yaml.MappingNode):
                for key_node, _ in node.value:
                    if key_node.tag == "tag:yaml.org,2002:merge":
                        continue
                    key = self.construct_object(key_node, deep=True) if isinstance(key_node, yaml.ScalarNode) \
                        else None
                    if key is None and not isinstance(key_node, yaml.ScalarNode):
                        continue              # an unhashable key: the base class says so
                    try:
                        if key in seen:
                            raise ConstructorError(None, None, f"key {key!r} is given twice", key_node.start_mark)
                        seen.add(key)
                    except TypeError:
                        pass
            return super().construct_mapping(node, deep)

        def construct_yaml_int(self, node):
            value = self.construct_scalar(node)
            if len(value) > MAX_DIGITS:
                raise ConstructorError(None, None, f"an integer of {len(value)} characters; at most {MAX_DIGITS} "
                                       "digits", node.start_mark)
            return super().construct_yaml_int(node)

    Loader.add_constructor("tag:yaml.org,2002:int", Loader.construct_yaml_int)
    _loader = Loader
    return Loader


def load_yaml(text: str, name: str = "document"):
    """The value of the YAML ``text`` (one document; see the module's description)."""
    loader = _yaml_loader(name)
    import yaml

    try:
        return yaml.load(text, Loader=loader)      # noqa: S506 - the safe loader, refusing more
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        what = e.problem or e.context or "not valid YAML"
        if e.context and e.problem and e.context not in what:
            what = f"{e.context}: {what}"
        where = f"{name}:{mark.line + 1}" if mark is not None else name
        raise DocumentError(f"{where}: {' '.join(str(what).split())}") from None
    except yaml.reader.ReaderError as e:
        ch = e.character if isinstance(e.character, int) else ord(str(e.character)[:1] or "\0")
        raise DocumentError(f"{name}:{line_of(text, e.position)}: character U+{ch:04X} is not allowed "
                            "in YAML") from None
    except yaml.YAMLError as e:
        raise DocumentError(f"{name}: not valid YAML: {' '.join(str(e).split())}") from None
    except RecursionError:
        raise DocumentError(f"{name}: nested more than {MAX_DEPTH} levels deep") from None
