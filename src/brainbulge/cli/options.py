"""Command-line options built from a case dataclass's fields (:mod:`brainbulge.model.options`):
type, default, range and help come from the field; the case checks the values."""

from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from typing import Any

from brainbulge.cli import whole_number


def flag(f: dataclasses.Field) -> str:
    """The command-line option of field ``f`` (``--mesh-size`` for ``mesh_size``)."""
    return f.metadata.get("flag") or "--" + f.name.replace("_", "-")


def cli_fields(cls: type) -> list[dataclasses.Field]:
    """The fields of case ``cls`` that are command-line options (not ``internal``)."""
    return [f for f in dataclasses.fields(cls) if not f.metadata.get("internal")]


def _help(f: dataclasses.Field, default_text: str | None) -> str:
    meta = f.metadata
    unit = meta["unit"].strip()
    text = meta["help"] + (f" [{'units of ' if unit == 'R' else ''}{unit}]" if unit else "")
    shown = []
    if default_text is not None:
        shown.append(default_text)
    elif isinstance(f.default, tuple):
        shown.append(f"default {' '.join(f'{v:g}' for v in f.default)}")
    elif f.default is not None and not isinstance(f.default, bool):
        shown.append(f"default {f.default:g}" if isinstance(f.default, float | int)
                     else f"default {f.default}")
    if meta.get("range") is not None:
        lo, hi = (b.replace("_", " ") if isinstance(b, str) else f"{b:d}" if isinstance(b, int)
                  else f"{b:g}" for b in meta["range"])
        shown.append(f"range [{lo}, {hi}]")
    return text + (f" ({'; '.join(shown)})" if shown else "")


def add_case_options(p: Any, cls: type, default_text: dict[str, str] | None = None,
                     names: tuple[str, ...] | None = None,
                     required: tuple[str, ...] = ()) -> None:
    """One option per command-line field of case ``cls`` (those of ``names`` if given) on
    parser or group ``p``; an option left out is absent from the parsed arguments, so the
    case's default applies. ``default_text``: how the help states a default that depends on
    other fields or is the command's own (field name -> text); ``required``: the fields that
    must be given. A list field takes its ``metavar`` items (one metavar: one or more
    numbers); a list of such lists, the option repeated."""
    hints = typing.get_type_hints(cls)
    for f in cli_fields(cls):
        if names is not None and f.name not in names:
            continue
        hint = hints[f.name]
        tp = ([a for a in typing.get_args(hint) if a is not type(None)]
              if typing.get_origin(hint) in (typing.Union, types.UnionType) else [hint])
        shown = "required" if f.name in required else (default_text or {}).get(f.name)
        kw: dict[str, Any] = {"dest": f.name, "default": argparse.SUPPRESS,
                              "help": _help(f, shown)}
        if tp[0] is bool:
            kw["action"] = argparse.BooleanOptionalAction
            kw["help"] += f" (default {'on' if f.default else 'off'})"
        elif typing.get_origin(tp[0]) in (list, tuple):
            metavar = f.metadata["metavar"]
            kw.update(type=float, nargs="+" if len(metavar) == 1 else len(metavar),
                      metavar=metavar[0] if len(metavar) == 1 else metavar)
            if typing.get_origin(typing.get_args(tp[0])[0]) is list:
                kw["action"] = "append"
        elif f.metadata["choices"]:
            kw["choices"] = f.metadata["choices"]
        elif tp[0] is int:
            kw["type"] = whole_number(flag(f))  # 1e5 and 100_000 too, as the help writes them
        else:
            kw["type"] = tp[0]
        if tp[0] in (int, float, str) and not f.metadata["choices"]:
            kw["metavar"] = flag(f).removeprefix("--").replace("-", "_").upper()
        if f.name in required:
            kw.update(required=True, default=None)
        p.add_argument(flag(f), **kw)


def option_names(cls: type, *exclude: str) -> tuple[str, ...]:
    """The command-line fields of case ``cls`` but ``exclude``."""
    return tuple(f.name for f in cli_fields(cls) if f.name not in exclude)


def field_default(cls: type, name: str) -> Any:
    """The default of field ``name`` of case ``cls``."""
    f = next(f for f in dataclasses.fields(cls) if f.name == name)
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


def case_config(args: argparse.Namespace, cls: type) -> dict[str, Any]:
    """The case options given on the command line (the others take the case's defaults)."""
    return {f.name: getattr(args, f.name) for f in cli_fields(cls) if hasattr(args, f.name)}
