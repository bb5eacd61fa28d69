"""Command-line options built from a case dataclass's fields (:mod:`brainbulge.model.options`):
type, default, range and help come from the field; the case checks the values."""

from __future__ import annotations

import argparse
import dataclasses
import typing
from typing import Any


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
    elif f.default is not None and not isinstance(f.default, bool):
        shown.append(f"default {f.default:g}" if isinstance(f.default, float | int)
                     else f"default {f.default}")
    if meta.get("range") is not None:
        lo, hi = (b.replace("_", " ") if isinstance(b, str) else f"{b:g}" for b in meta["range"])
        shown.append(f"range [{lo}, {hi}]")
    return text + (f" ({'; '.join(shown)})" if shown else "")


def add_case_options(p: argparse.ArgumentParser, cls: type,
                     default_text: dict[str, str] | None = None,
                     names: tuple[str, ...] | None = None) -> None:
    """One option per command-line field of case ``cls`` (those of ``names`` if given); an
    option left out is absent from the parsed arguments, so the case's default applies.
    ``default_text``: how the help states a default that depends on other fields (field
    name -> text)."""
    hints = typing.get_type_hints(cls)
    for f in cli_fields(cls):
        if names is not None and f.name not in names:
            continue
        tp = [a for a in typing.get_args(hints[f.name]) if a is not type(None)] or [hints[f.name]]
        kw: dict[str, Any] = {"dest": f.name, "default": argparse.SUPPRESS,
                              "help": _help(f, (default_text or {}).get(f.name))}
        if tp[0] is bool:
            kw["action"] = argparse.BooleanOptionalAction
            kw["help"] += f" (default {'on' if f.default else 'off'})"
        elif typing.get_origin(tp[0]) is list:
            kw.update(type=float, nargs=len(f.metadata["metavar"]),
                      metavar=f.metadata["metavar"])
        elif f.metadata["choices"]:
            kw["choices"] = f.metadata["choices"]
        else:
            kw["type"] = tp[0]
        p.add_argument(flag(f), **kw)


def case_config(args: argparse.Namespace, cls: type) -> dict[str, Any]:
    """The case options given on the command line (the others take the case's defaults)."""
    return {f.name: getattr(args, f.name) for f in cli_fields(cls) if hasattr(args, f.name)}
