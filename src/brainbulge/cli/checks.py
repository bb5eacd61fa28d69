"""Input checks run before ``--out`` is touched: types, ranges, files, addresses.

Each failure is an `InputError` whose one line names the option, the value, the allowed
range and what to do. The ranges keep a run within what finishes in minutes to hours on a
workstation and what Netgen can mesh (docs/model.md, docs/outputs.md "Exit codes").
"""

from __future__ import annotations

import logging
import math
import re
import socket
import threading
import types
import typing
from pathlib import Path
from typing import Any, Union

from brainbulge.errors import BrainbulgeError, InputError
from brainbulge.model.brain_case import LABELS_TETS_PER_ML, TEMPLATE_TETS_MIN, TETS_RANGE
from brainbulge.model.options import number

log = logging.getLogger(__name__)

#: a custom flap centre must lie near the skull: |x|, |y|, |z| at most this [mm, RAS]
FLAP_CENTRE_MM = 150.0
#: local Dask worker processes (``--workers``)
WORKERS = (1, 256)
#: Dask scheduler addresses: ``[protocol://]host:port``
SCHEDULER = re.compile(r"((tcp|tls|inproc|ucx|ws|wss)://)?[A-Za-z0-9_.\-\[\]:]*[A-Za-z0-9\]]:\d{1,5}")
#: seconds a Dask scheduler has to accept a connection before a study is refused
SCHEDULER_PROBE_S = 5.0
#: ``--worker-wait``: seconds a Dask scheduler without workers is waited on before the
#: command is refused (a batch system may take minutes to start them), and its range
WORKER_WAIT_S = 600.0
WORKER_WAIT_RANGE = (0.0, 86_400.0)
#: seconds between two questions to a scheduler without workers (the first is at once, so
#: "no workers" is said within `SCHEDULER_PROBE_S` of the start)
WORKER_POLL_S = 2.0


# --------------------------------------------------------------------------- generic


def _describe(tp: Any) -> str:
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    if typing.get_origin(tp) in (Union, types.UnionType):
        return " or ".join(_describe(a) for a in args)
    if tp is float:
        return "a number"
    if tp is int:
        return "a whole number"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "text in quotes"
    if typing.get_origin(tp) in (list, tuple):
        return "a list of numbers" if args and args[0] in (float, int) else "a list"
    return "a table" if tp is dict or typing.get_origin(tp) is dict else str(tp)


def _matches(value: Any, tp: Any) -> bool:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return True
    if origin in (Union, types.UnionType):
        return any(_matches(value, a) for a in args)
    if tp is type(None):
        return value is None
    if tp is bool:
        return isinstance(value, bool)
    if tp is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if tp is str:
        return isinstance(value, str)
    if origin in (list, tuple) or tp in (list, tuple):
        if not isinstance(value, list | tuple):
            return False
        if origin is tuple and args and args[-1] is not Ellipsis:
            return len(value) == len(args) and all(map(_matches, value, args))
        return not args or all(_matches(v, args[0]) for v in value)
    if tp is dict or origin is dict:
        return isinstance(value, dict)
    return True


def check_types(cls: type, config: dict[str, Any], what: str) -> None:
    """Every known key of ``config`` has the type of ``cls``'s field (TOML tables)."""
    hints = typing.get_type_hints(cls)
    for key, value in config.items():
        if key in hints and not _matches(value, hints[key]):
            raise InputError(f"{what} option {key} = {value!r} must be "
                             f"{_describe(hints[key])}; correct it in the TOML file")


# --------------------------------------------------------------------------- hemidisk


def hemidisk_case(config: dict[str, Any]) -> Any:
    """A checked :class:`~brainbulge.model.hemidisk.HemidiskCase` from a plain dict."""
    from brainbulge.model.hemidisk import HemidiskCase
    from brainbulge.studies.hemidisk import case_from_dict

    check_types(HemidiskCase, {k: v for k, v in config.items() if k != "name"}, "hemidisk")
    case = case_from_dict(config)  # the case checks its own ranges
    case.geometry  # noqa: B018 - angles, opening, disk position
    case.rigid_skull  # noqa: B018 - cut-edge radius against the skull's thickness
    case.tissue_material()
    return case


# --------------------------------------------------------------------------- brain


def brain_npz(path: str | Path, what: str = "--mesh") -> None:
    """``path`` (or ``path/brain.npz``) reads as a brain mesh written by ``brainbulge mesh``."""
    from brainbulge.geometry.brain import load_brain_mesh

    p = Path(path)
    p = p / "brain.npz" if p.is_dir() else p
    if not p.is_file():
        raise InputError(f"{what} {path}: no such file; build one with `brainbulge mesh --out "
                         "DIR` and pass DIR/brain.npz")
    st = p.stat()
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns)
    if key in _READABLE:  # a study's scenarios share one mesh
        return
    try:
        load_brain_mesh(p)  # every array checked (index range, NaN, codes, volumes)
    except BrainbulgeError:
        raise
    except Exception:  # noqa: BLE001 - truncated, foreign, text: all the same to the user
        raise InputError(f"{what} {path} is not a brain.npz written by `brainbulge mesh` "
                         "(unreadable or other arrays); build one with `brainbulge mesh "
                         "--out DIR` and pass DIR/brain.npz") from None
    _READABLE.add(key)


_READABLE: set[tuple[str, int, int]] = set()


def flap_centre(centre: Any) -> None:
    if centre is None:
        return
    if len(centre) != 3 or not all(math.isfinite(c) and abs(c) <= FLAP_CENTRE_MM
                                   for c in centre):
        raise InputError(
            f"--flap-centre {' '.join(f'{c:g}' for c in centre)} is not near the skull: give "
            f"a point on it, each coordinate within +-{FLAP_CENTRE_MM:g} mm (world RAS)")


def brain_case(config: dict[str, Any]) -> Any:
    """A checked :class:`~brainbulge.model.brain.CraniectomyCase` from a plain dict."""
    from brainbulge.model.brain_case import CraniectomyCase
    from brainbulge.studies.craniectomy import case_from_dict

    check_types(CraniectomyCase, {k: v for k, v in config.items() if k != "name"}, "brain")
    case = case_from_dict(config)  # the case checks its own ranges
    flap_centre(case.flap_centre_mm)
    if case.fibres is not None:
        from brainbulge.geometry.brain.fibres import check_fibres

        check_fibres(case.fibres)  # its header: shape and size, not its data
    if case.mesh is None:
        labelled = None if case.labels is None else labelled_ml(case.labels, case.label_map)
        mesh_tets(case.tets, case.refine, template=case.labels is None, labelled_ml=labelled)
    if case.mesh is not None:
        brain_npz(case.mesh)
    return case


def mesh_tets(tets: Any, refine: Any, template: bool, labelled_ml: float | None = None
              ) -> None:
    """A brain mesh of about ``tets`` tets made at ``tets / 8**refine`` and refined; of the
    ICBM152 template (``template``) at least `TEMPLATE_TETS_MIN` before refinement, of a
    segmentation with ``labelled_ml`` ml of tissue at least `LABELS_TETS_PER_ML` per ml."""
    number("--refine", refine, 0, 3, integer=True)
    made = f"--tets {tets}" + (f" / 8^{refine}" if refine else "")
    whole = isinstance(tets, int) and not isinstance(tets, bool)
    if template and whole and tets / 8**refine < TEMPLATE_TETS_MIN:
        raise InputError(
            f"{made} is below {TEMPLATE_TETS_MIN:,}: Netgen cannot mesh the ICBM152 template "
            f"that coarse (it retries for minutes); give --tets {TEMPLATE_TETS_MIN * 8**refine} "
            "or more")
    lo = TEMPLATE_TETS_MIN * 8**refine if template else TETS_RANGE[0]  # the range that holds
    number("--tets", tets, min(lo, TETS_RANGE[1]), TETS_RANGE[1], integer=True)
    if labelled_ml is None:
        return
    least, safe = (math.ceil(rate * labelled_ml) * 8**refine for rate in LABELS_TETS_PER_ML)
    if tets < least:
        raise InputError(
            f"{made} is too coarse for {labelled_ml:,.0f} ml of labelled tissue: below "
            f"{LABELS_TETS_PER_ML[0]:.1f} tets per ml Netgen gives up on a brain's surface "
            f"(and retries for minutes); give --tets {least} or more (from {safe} it meshes "
            "the template)")
    if tets < safe:
        log.warning("%s for %.0f ml of labelled tissue is coarse: Netgen may retry for minutes; "
                    "from --tets %d it meshes the template", made, labelled_ml, safe)


def labelled_ml(labels: str | Path, label_map: Any) -> float:
    """Volume [ml] of all tissues of the segmentation ``labels`` (as `mesh` maps them)."""
    from brainbulge.geometry.brain import load_tissue_image

    p = Path(labels)
    try:
        st = p.stat()
    except OSError:
        raise InputError(f"--labels {labels}: no such file; give a NIfTI label image "
                         "(.nii/.nii.gz)") from None
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns, str(label_map))
    if key not in _LABELLED_ML:  # a study's scenarios share one segmentation
        volumes = load_tissue_image(p, label_map).volumes_ml()
        _LABELLED_ML[key] = float(sum(volumes.values()))
    return _LABELLED_ML[key]


_LABELLED_ML: dict[tuple[str, int, int, str], float] = {}


# --------------------------------------------------------------------------- study


def cluster(address: str | None, workers: int | None,
            worker_wait: float = WORKER_WAIT_S) -> None:
    """``--scheduler`` (:func:`scheduler`), ``--workers`` (None or within `WORKERS`) and
    ``--worker-wait`` (within `WORKER_WAIT_RANGE`)."""
    if workers is not None:
        number("--workers", workers, *WORKERS, integer=True)
    number("--worker-wait", worker_wait, *WORKER_WAIT_RANGE)
    scheduler(address, worker_wait)


def scheduler(address: str | None, worker_wait: float = WORKER_WAIT_S) -> None:
    """``None``, ``serial`` or a Dask address ``[tcp://]host:port`` at which something
    accepts a connection within `SCHEDULER_PROBE_S` (tcp, tls, ws, wss; inproc and ucx
    addresses are not probed) and, over tcp, a Dask scheduler answers that has a worker
    within ``worker_wait`` seconds (said on stderr at once if it has none)."""
    if address is None or address == "serial":
        return
    if not SCHEDULER.fullmatch(address):
        raise InputError(
            f"--scheduler {address!r} is not a Dask scheduler address; give one such as "
            "tcp://10.0.0.5:8786, 'serial', or leave it out for a local cluster")
    protocol, _, rest = address.rpartition("://")
    if protocol not in ("", "tcp", "tls", "ws", "wss"):
        return
    host, _, port = rest.rpartition(":")
    if not 1 <= int(port) <= 65535:
        raise InputError(f"--scheduler {address}: port {port} must lie in [1, 65535]; give the "
                         "port the scheduler prints (8786 by default)")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), SCHEDULER_PROBE_S):
            pass
    except OSError as exc:
        reason = (f"no answer in {SCHEDULER_PROBE_S:g} s" if isinstance(exc, TimeoutError)
                  else exc.strerror or str(exc))
        raise InputError(
            f"--scheduler {address}: no Dask scheduler reachable there ({reason.lower()}); "
            "start one (`dask scheduler`) or correct the address, or leave --scheduler out "
            "for a local cluster") from None
    if protocol not in ("", "tcp"):
        return  # a handshake over TLS or websockets needs the cluster's security settings
    full = address if protocol else f"tcp://{address}"
    reply = _identity(full)
    if not (isinstance(reply, dict) and reply.get("type") == "Scheduler"):
        raise InputError(
            f"--scheduler {address}: something listens there, but it is not a Dask scheduler "
            f"(no Dask handshake in {SCHEDULER_PROBE_S:g} s); give the scheduler's address "
            "(`dask scheduler` prints it), or leave --scheduler out for a local cluster")
    _wait_for_workers(address, full, reply, worker_wait)


def _wait_for_workers(address: str, full: str, reply: dict, worker_wait: float) -> None:
    """Return once the scheduler at ``full`` (whose ``identity`` is ``reply``) has a worker;
    say so at once if it has none; `InputError` if none joins within ``worker_wait`` s."""
    import time

    deadline = time.monotonic() + worker_wait
    said = False
    while not (isinstance(reply, dict) and reply.get("workers")):
        if not said:
            log.warning("no workers at %s; waiting up to %g s for one (--worker-wait)",
                        address, worker_wait)
            said = True
        if time.monotonic() >= deadline:
            raise InputError(
                f"--scheduler {address}: no workers joined it in {worker_wait:g} s; start "
                f"workers (`dask worker {full}`), give --worker-wait more seconds, or leave "
                "--scheduler out for a local cluster")
        time.sleep(max(0.0, min(WORKER_POLL_S, deadline - time.monotonic())))
        reply = _identity(full)
    if said:
        log.warning("a worker joined %s; going on", address)


def _identity(address: str) -> Any:
    """The Dask ``identity`` reply of the server at ``address``, within
    `SCHEDULER_PROBE_S` seconds in all; None if there is none (another kind of server)."""
    import asyncio

    from distributed.comm import connect

    async def ask() -> Any:
        comm = await connect(address, timeout=SCHEDULER_PROBE_S)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def probe(found: list[Any]) -> None:  # in its own thread: the caller may run a loop
        try:
            found.append(asyncio.run(asyncio.wait_for(ask(), SCHEDULER_PROBE_S)))
        except Exception:  # noqa: BLE001 - a timeout, a refused or garbled handshake
            pass

    found: list[Any] = []
    thread = threading.Thread(target=probe, args=(found,), daemon=True)
    thread.start()
    thread.join(SCHEDULER_PROBE_S + 1.0)
    return found[0] if found else None
