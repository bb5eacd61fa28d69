"""The ``brainbulge`` command line: thin; parses, validates, calls the API.

Every command checks all its inputs first, then claims ``--out`` (refused if it exists and
is not empty, unless ``--overwrite``, which deletes only files brainbulge wrote; locked while
the run lasts), records ``run.toml`` (the resolved configuration, which ``brainbulge run``
accepts back), ``run.json`` (versions, command, the files written) and ``status.json``, and
logs to ``brainbulge.log``. Errors are one line on stderr with a non-zero exit code;
``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import errno
import logging
import signal
import sys
import threading
import time
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from brainbulge import __version__
from brainbulge.errors import BrainbulgeError, InputError
from brainbulge.runtime import STOP_SIGNALS
from brainbulge.runtime import configure as configure_runtime

log = logging.getLogger("brainbulge")

EXIT_INTERRUPTED = 130

#: errno values of a write that failed for lack of space or permission (one line, exit 2)
_DISK_FULL = (errno.ENOSPC, errno.EDQUOT)
_NO_WRITE = (errno.EROFS, errno.EACCES, errno.EPERM, errno.ENAMETOOLONG)


class Terminated(KeyboardInterrupt):
    """One of `STOP_SIGNALS` (a batch system's time limit or its warning before it, a closed
    terminal or SSH connection): handled as an interruption."""

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signal_name = signal.Signals(signum).name


class _QuietStream:
    """stdout or stderr whose failures never fail a run: the first write or flush that fails
    (a closed pipe, ``> /dev/full``) sends the rest to the null device; the run goes on and
    its status tells what it computed."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except (OSError, ValueError):
            self._silence()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except (OSError, ValueError):
            self._silence()

    def _silence(self) -> None:
        import os

        try:
            null = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(null, self._stream.fileno())
            finally:
                os.close(null)
        except (OSError, ValueError, AttributeError):
            pass  # a stream without a file (a test's capture): its writes are dropped

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


@dataclass
class _Run:
    """The output folder this process owns (claimed and locked by `start_run`)."""

    folder: Any = None
    log_handler: logging.Handler | None = None
    started: float = field(default_factory=time.time)


_RUN = _Run()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``brainbulge`` console script; returns the exit code (0 done, 2 bad
    input or unusable output folder, 3 infeasible, 4 not converged / incomplete, 5 mesh
    error, 130 interrupted; 1 only for internal errors)."""
    global _RUN
    parser = build_parser()
    args = parser.parse_args(argv)
    streams = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _QuietStream(sys.stdout), _QuietStream(sys.stderr)
    try:
        return _main(parser, args)
    finally:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        sys.stdout, sys.stderr = streams


def run_parsed(args: argparse.Namespace) -> int:
    """Run a parsed command (``args.func``) as :func:`main` does: runtime tuning, signals,
    the output folder's status and lock; errors raised with ``args.debug``. The Python
    API's entry (:mod:`brainbulge.api`)."""
    return _main(build_parser(), args)


def _main(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    global _RUN
    _setup_logging(args.verbose)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    configure_runtime()  # threads, MKL, heap, compiler cache: before NGSolve loads
    _RUN = _Run()
    previous = {signum: _on_signal(signum, _raise_terminated) for signum in STOP_SIGNALS}
    previous_alarm, previous_unraisable = signal.getsignal(signal.SIGALRM), sys.unraisablehook
    sys.unraisablehook = _dropped_stop
    try:
        return int(args.func(args) or 0)
    except BrainbulgeError as err:
        _mark("failed" if err.exit_code != 4 else "incomplete", str(err))
        if args.debug:
            raise
        print(f"error: {_line(err)}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt as err:
        _end_children()
        how = (f"stopped by {err.signal_name}" if isinstance(err, Terminated)
               else "interrupted by the user")
        _mark("incomplete", how)
        print(f"interrupted: {_kept()}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as err:
        if err.errno not in (*_DISK_FULL, *_NO_WRITE) or args.debug:
            return _internal(err, args.debug)
        if _RUN.folder is not None and err.errno in _DISK_FULL:
            _RUN.folder.drop_empty_files()
        _mark("failed", _os_message(err))
        print(f"error: {_os_message(err)}", file=sys.stderr)
        return InputError.exit_code
    except Exception as err:  # an unexpected failure: still one line unless --debug
        return _internal(err, args.debug)
    except BaseException:  # SystemExit from a library, or worse: the status still tells
        _mark("failed", "ended without finishing (an unexpected exit)")
        raise
    finally:
        for signum, handler in previous.items():
            _on_signal(signum, handler)
        sys.unraisablehook = previous_unraisable
        if signal.getsignal(signal.SIGALRM) is not previous_alarm:  # a dropped stop re-asked
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous_alarm or signal.SIG_DFL)
        _release()


def _internal(err: Exception, debug: bool) -> int:
    _mark("failed", repr(err))
    if debug:
        raise err
    print(f"error: internal error ({type(err).__name__}: {_line(err) or type(err).__name__}); "
          "rerun with --debug and report it", file=sys.stderr)
    return 1


def _line(err: BaseException) -> str:
    return " ".join(str(err).split())


def _os_message(err: OSError) -> str:
    """One line for a failed write: what, why, what to do."""
    out = _RUN.folder.path if _RUN.folder is not None else None
    inside = out is not None and err.filename is not None and (
        Path(out).resolve() in (target := Path(str(err.filename)).resolve()).parents
        or Path(out).resolve() == target)
    what = (f"cannot write {err.filename}" if inside else f"cannot access {err.filename}"
            if err.filename else "cannot write the results")
    why = (err.strerror or str(err)).rstrip(".").lower()
    if err.errno in _DISK_FULL:
        kept = f"; results written so far are kept in {out}" if out is not None else ""
        return f"{what}: {why}; free some space or choose another --out{kept}"
    if err.errno == errno.ENAMETOOLONG:
        return f"{what}: {why}; choose a shorter --out (or shorter scenario names)"
    writing = inside or not err.filename or err.errno == errno.EROFS
    return f"{what}: {why}; " + ("choose a writable --out" if writing
                                 else "check that the file is readable")


def _raise_terminated(signum: int, frame: Any) -> None:
    raise Terminated(signum)


def _dropped_stop(hook: Any) -> None:
    """``sys.unraisablehook`` while a command runs. Python drops an exception raised while it
    runs a finaliser (``__del__``, a weakref callback): a dropped :class:`Terminated` is
    raised again 0.05 s later (SIGALRM), so the stop still reaches the command's handler."""
    if not isinstance(hook.exc_value, Terminated):
        sys.__unraisablehook__(hook)
    elif threading.current_thread() is threading.main_thread():
        signum = signal.Signals[hook.exc_value.signal_name]
        signal.signal(signal.SIGALRM, lambda *_: _raise_terminated(signum, None))
        signal.setitimer(signal.ITIMER_REAL, 0.05)


def _on_signal(signum: int, handler: Any) -> Any:
    """Install ``handler`` for ``signum`` (main thread only); return the previous one. A
    signal ignored by whoever started brainbulge (``nohup`` ignores SIGHUP) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        return None
    if handler is None or signal.getsignal(signum) is signal.SIG_IGN:
        return None
    return signal.signal(signum, handler)


def _end_children(grace: float = 2.0) -> None:
    """End the child processes this command started (Netgen's mesher, Dask workers): SIGTERM,
    then SIGKILL for those still running after ``grace`` seconds."""
    try:
        import psutil

        children = [c for c in psutil.Process().children(recursive=True)
                    if c.create_time() >= _RUN.started - 1.0]
        for child in children:
            child.terminate()
        _, alive = psutil.wait_procs(children, timeout=grace)
        for child in alive:
            child.kill()
    except Exception as exc:  # noqa: BLE001 - psutil missing or a child already gone
        log.debug("ending child processes: %s", exc)


#: files that record a run rather than hold its results (by name, in any subfolder)
_BOOKKEEPING = frozenset({"run.json", "run.toml", "status.json", "brainbulge.log", "study.json",
                          "scenario.json", "error.json", "restart.npz", "spec.json"})


def _kept() -> str:
    """What an interruption left in the output folder, truthfully."""
    folder = _RUN.folder
    if folder is None:
        return "nothing was written"
    written = folder.written() | (set(folder.previous) if folder.resumed else set())
    results = [f for f in written if Path(f).name not in _BOOKKEEPING]
    again = any((folder.path / n).is_file() for n in ("study.json", "restart.npz"))
    resume = "; rerun the same command to resume" if again else ""
    if not results:
        return (f"stopped before any results were written; {folder.path} holds the run "
                f"record only{resume}")
    return f"results finished so far are kept in {folder.path}{resume}"


def _mark(status: str, message: str) -> None:
    """Record ``status`` in the output folder, only if this process owns it."""
    if _RUN.folder is None:
        return
    from brainbulge.results.records.run_record import mark_status

    try:
        mark_status(_RUN.folder.path, status, message)
    except OSError as exc:  # e.g. the disk is full
        log.info("could not record the status in %s: %s", _RUN.folder.path,
                    exc.strerror or exc)


def _release() -> None:
    if _RUN.log_handler is not None:
        log.removeHandler(_RUN.log_handler)
        _RUN.log_handler.close()
    if _RUN.folder is not None:
        _RUN.folder.release()


def _setup_logging(verbose: int) -> None:
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(message)s", stream=sys.stderr)
    log.setLevel(min(level, logging.INFO))
    for h in logging.getLogger().handlers:
        h.setLevel(level)


def add_log_file(out: Path) -> logging.Handler:
    """Also log (INFO and above) to ``out/brainbulge.log``."""
    from brainbulge.atomic import note_written

    handler = logging.FileHandler(Path(out) / "brainbulge.log")
    note_written(Path(out) / "brainbulge.log", tracked=False)  # it grows while the run goes on
    handler.setLevel(logging.INFO)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    log.addHandler(handler)
    return handler


def progress_bar() -> bool:
    """Progress bars only on a terminal; logs get plain lines (``brainbulge.log``, ``-v``)."""
    return sys.stderr.isatty()


def start_run(args: argparse.Namespace, config: dict[str, Any], resume: bool = False) -> Path:
    """Claim ``--out`` (checked, created, locked; cleared only with ``--overwrite``), write the
    run record, mark it running, start the log file. Call only after every input is checked."""
    from brainbulge.results.records.output_folder import claim_output_dir, config_paths
    from brainbulge.results.records.run_record import mark_status, write_run_record

    inputs = [*config_paths(config), getattr(args, "config", None)]  # never deleted
    folder = claim_output_dir(args.out, overwrite=args.overwrite, resume=resume,
                              config=config, inputs=inputs)
    _RUN.folder = folder
    out = folder.path
    write_run_record(out, config, None, files=folder.previous)
    mark_status(out, "running")
    _RUN.log_handler = add_log_file(out)
    return out


def finish_run(out: Path, message: str = "") -> None:
    from brainbulge.results.present.html_report import write_missing_html
    from brainbulge.results.records.run_record import mark_status

    write_missing_html(out)  # report.html next to each report.md written without one
    mark_status(out, "complete", message)
    print(f"results in {out}")


# --- parser ---------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit 2) that point to ``--help``."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, f"error: {' '.join(message.split())}; see `{self.prog} --help`\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
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
    from brainbulge.cli import brain, demo, hemidisk, mesh, plan, reproduce, run, study

    for module in (hemidisk, brain, study, plan, demo, reproduce, run, mesh):
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


def whole_number(name: str) -> Callable[[str], int]:
    """argparse type: a whole number, also written as ``1e5`` or ``100_000`` (as the help's
    defaults are), with a one-line error naming the option."""

    def parse(text: str) -> int:
        try:
            return int(text)
        except ValueError:
            pass
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{name} must be a whole number, got {text!r}") from None
        if not v.is_integer():
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text}")
        return int(v)

    return parse


def add_output_options(p: argparse.ArgumentParser, default_out: str) -> None:
    p.add_argument("--out", default=default_out, help=f"output folder (default {default_out})")
    p.add_argument(
        "--overwrite", action="store_true", help="replace an existing brainbulge output folder"
    )


def add_cluster_options(p: argparse.ArgumentParser, what: str = "",
                        workers_note: str = "") -> None:
    """``--scheduler``, ``--workers`` and ``--worker-wait`` (checked by
    :func:`brainbulge.cli.checks.cluster`);
    ``what``: the runs they apply to, as a prefix of the help."""
    prefix = f"{what}: " if what else ""
    p.add_argument("--scheduler", default=None,
                   help=f"{prefix}address of a running Dask scheduler (default: a local "
                   "cluster); 'serial' runs in this process")
    p.add_argument("--workers", type=whole_number("--workers"), default=None,
                   help=f"{prefix}local worker processes{workers_note}")
    from brainbulge.cli.checks import WORKER_WAIT_RANGE, WORKER_WAIT_S

    p.add_argument("--worker-wait", type=float, default=WORKER_WAIT_S, metavar="S",
                   help=f"{prefix}seconds to wait for a worker of a --scheduler that has none "
                   f"before giving up (default {WORKER_WAIT_S:g}; range "
                   f"[{WORKER_WAIT_RANGE[0]:g}, {WORKER_WAIT_RANGE[1]:g}])")


def require(cond: bool, message: str) -> None:
    """Refuse the command with ``message`` (one line, exit 2) unless ``cond`` holds."""
    if not cond:
        raise InputError(message)
