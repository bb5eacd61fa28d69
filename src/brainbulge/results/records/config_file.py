"""Configuration files: a configuration as TOML can hold it, and a TOML file read back with
one-line errors.

>>> toml_ready({"mesh": (1, 2), "seed": None})
{'mesh': [1, 2]}
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import re
import tomllib
from collections.abc import Mapping
from datetime import date, datetime, time
from pathlib import Path, PurePath
from typing import Any

from brainbulge.atomic import read_regular
from brainbulge.errors import InputError


def toml_ready(value: Any, _where: str = "config") -> Any:
    """Convert a configuration to what TOML can hold.

    Tuples/sets -> lists, paths -> str, enums -> their value, dataclasses -> tables, numpy
    scalars/arrays -> Python numbers/lists; keys whose value is None are dropped (TOML has no
    null). Raises TypeError naming the offending key for anything else (or None in a list).
    """
    if value is None:
        raise TypeError(f"{_where}: None inside a list cannot be written to TOML")
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"{_where}: key {key!r} is not a string")
            if item is None:
                continue
            out[key] = toml_ready(item, f"{_where}.{key}")
        return out
    if isinstance(value, enum.Enum):
        return toml_ready(value.value, _where)
    if isinstance(value, bool | int | float | str | datetime | date | time):
        return value
    if isinstance(value, PurePath):
        return str(value)
    if hasattr(value, "tolist") and callable(value.tolist):  # numpy scalar or array
        return toml_ready(value.tolist(), _where)
    if isinstance(value, list | tuple):
        return [toml_ready(item, f"{_where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, set | frozenset):
        return [toml_ready(item, f"{_where}[]") for item in sorted(value)]
    raise TypeError(f"{_where}: {type(value).__name__} cannot be written to TOML")


def load_config(path: Path) -> dict[str, Any]:
    """Read a TOML configuration file; `InputError` (one line, with the line number of a
    syntax error) if it is missing, unreadable or not valid TOML."""
    path = Path(path)
    try:
        data = read_regular(path, follow_links=True)  # a FIFO or a device: refused, not read
    except OSError as exc:
        raise InputError(f"cannot read config {path}: {exc.strerror or exc}") from exc
    try:
        text = data.decode("utf-8-sig")  # a byte-order mark, as Windows editors write one
    except UnicodeDecodeError as exc:
        raise InputError(
            f"config {path} is not UTF-8 text (byte {exc.start}); save it as UTF-8"
        ) from exc
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc).splitlines()[0] if str(exc) else "syntax error"
        lineno = getattr(exc, "lineno", None)  # attribute exists from Python 3.14 on
        if lineno is None:
            found = re.search(r"line (\d+)", msg)
            lineno = int(found.group(1)) if found else None
        msg = re.sub(r"\s*\(at (line \d+, column \d+|end of document)\)\s*$", "", msg)
        where = f"line {lineno}" if lineno is not None else "end of file"
        raise InputError(f"invalid TOML in {path}, {where}: {msg}") from exc
    except RecursionError:
        raise InputError(f"invalid TOML in {path}: tables or lists nested too deeply to read; "
                         "a run file needs at most a few levels") from None


def _is_table(sub: Any) -> bool:
    """Whether a schema entry describes a table or an array of tables (not a value)."""
    return isinstance(sub, dict | list)


#: A run file's schema: key -> None (a value of any kind), a schema (a table) or a list of
#: one schema (an array of tables)
Schema = dict[str, Any]


def check_keys(config: Mapping[str, Any], schema: Schema, where: str, _table: str = "") -> None:
    """Refuse (`InputError`, one line) a table or key of ``config`` that ``schema`` does not
    know, naming the nearest valid one, or where it belongs if it is valid in another table;
    a value of the wrong kind (a table for a value, a value for a table) likewise."""
    for key, value in config.items():
        name = f"{_table}.{key}" if _table else key
        if key not in schema:
            table = isinstance(value, Mapping)
            kind = "table" if table else "option"
            shown = f"[{name}]" if table else key
            homes = [t for t, sub in schema.items() if isinstance(sub, dict) and key in sub
                     and _is_table(sub[key]) == table]
            # a table is matched against tables only, an option against anything
            names = [k for k, sub in schema.items() if _is_table(sub) or not table]
            near = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
            if homes:
                hint = f"it belongs in [{_table + '.' if _table else ''}{homes[0]}]"
            elif near:
                hint = f"did you mean [{near[0]}]?" if table else f"did you mean {near[0]!r}?"
            elif names:
                hint = f"valid {'tables ' if table else ''}here: {', '.join(sorted(names))}"
            else:
                hint = f"[{_table}] holds options only; write them under [{_table}]"
            raise InputError(f"{where}: unknown {kind} {shown}" + (
                f" in [{_table}]" if _table and kind == "option" else "") + f"; {hint}")
        sub = schema[key]
        if isinstance(sub, dict):
            if not isinstance(value, Mapping):
                raise InputError(f"{where}: {name} must be a table ([{name}]) of options")
            check_keys(value, sub, where, name)
        elif isinstance(sub, list):
            if not isinstance(value, list) or not all(isinstance(v, Mapping) for v in value):
                raise InputError(f"{where}: {name} must be an array of tables ([[{name}]])")
            for item in value:
                check_keys(item, sub[0], where, name)
