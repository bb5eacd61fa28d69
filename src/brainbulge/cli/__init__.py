"""The ``brainbulge`` command line: thin; parses, validates, calls the API.

Every command writes into ``--out`` (refused if it exists and is not empty, unless
``--overwrite``), records ``run.toml`` (the resolved configuration, which ``brainbulge run``
accepts back), ``run.json`` (versions, command) and ``status.json``, and logs to
``brainbulge.log``. Errors are one line on stderr with a non-zero exit code; ``--debug`` shows
the traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from brainbulge import __version__
from brainbulge.errors import BrainbulgeError
from brainbulge.runtime import configure as configure_runtime

log = logging.getLogger("brainbulge")

EXIT_INTERRUPTED = 130


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``brainbulge`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    _setup_logging(args.verbose)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    configure_runtime()  # threads, MKL, heap, compiler cache: before NGSolve loads
    out = getattr(args, "out", None)
    try:
        return int(args.func(args) or 0)
    except BrainbulgeError as err:
        _mark(out, "failed" if err.exit_code != 4 else "incomplete", str(err))
        if args.debug:
            raise
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        _mark(out, "incomplete", "interrupted by the user")
        print("interrupted: results finished so far are kept in the output folder", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as err:  # an unexpected failure: still one line unless --debug
        _mark(out, "failed", repr(err))
        if args.debug:
            raise
        msg = " ".join(str(err).split()) or type(err).__name__
        print(
            f"error: internal error ({type(err).__name__}: {msg}); rerun with --debug and "
            "report it",
            file=sys.stderr,
        )
        return 1


def _mark(out: Any, status: str, message: str) -> None:
    if out is None:
        return
    from brainbulge.results.run_record import mark_status

    path = Path(out)
    if path.is_dir() and (path / "run.json").is_file():
        mark_status(path, status, message)


def _setup_logging(verbose: int) -> None:
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(message)s", stream=sys.stderr)
    log.setLevel(min(level, logging.INFO))
    for h in logging.getLogger().handlers:
        h.setLevel(level)


def add_log_file(out: Path) -> None:
    """Also log (INFO and above) to ``out/brainbulge.log``."""
    handler = logging.FileHandler(Path(out) / "brainbulge.log")
    handler.setLevel(logging.INFO)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    log.addHandler(handler)


def start_run(args: argparse.Namespace, config: dict[str, Any], resume: bool = False) -> Path:
    """Prepare ``--out``, write the run record, mark it running, start the log file."""
    from brainbulge.results.run_record import mark_status, prepare_output_dir, write_run_record

    out = prepare_output_dir(Path(args.out), overwrite=args.overwrite, resume=resume)
    write_run_record(out, config, None)
    mark_status(out, "running")
    add_log_file(out)
    return out


def finish_run(out: Path, message: str = "") -> None:
    from brainbulge.results.run_record import mark_status

    mark_status(out, "complete", message)
    print(f"results in {out}")


# --- parser ---------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="brainbulge",
        description="Finite-element simulation of brain swelling and decompressive "
        "craniectomy (Weickenmeier et al., 'Bulging brains', 2017).",
    )
    parser.add_argument("--version", action="version", version=f"brainbulge {__version__}")
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="more log output (-vv for Newton iterations)",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND")
    from brainbulge.cli import brain, demo, hemidisk, mesh, reproduce, run, study

    for module in (hemidisk, brain, study, demo, reproduce, run, mesh):
        module.add_parser(sub)
    return parser


def positive_float(name: str) -> Callable[[str], float]:
    """argparse type: a finite positive float with a one-line error naming the option."""

    def parse(text: str) -> float:
        import math

        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(v) or v <= 0:
            raise argparse.ArgumentTypeError(f"{name} must be a positive number, got {text}")
        return v

    return parse


def add_output_options(p: argparse.ArgumentParser, default_out: str) -> None:
    p.add_argument("--out", default=default_out, help=f"output folder (default {default_out})")
    p.add_argument(
        "--overwrite", action="store_true", help="replace an existing brainbulge output folder"
    )
