"""Shared real devices reserved through labgrid (SPEC §10): a lab file's `external: {labgrid:
PLACE}` on a Type I device (ATC, trackside) names a place of the test team's labgrid coordinator.
`lab up` acquires it, links its exported serial port (a `NetworkSerialPort`: the exporter serves
the device's serial line with ser2net over RFC 2217) through the link's tap as
`rfc2217://HOST:PORT`, and releases it when the lab ends -- however it ends.

labgrid is used, not rebuilt: everything goes through its own client, `labgrid-client -x
COORDINATOR -p PLACE acquire|env|release` (its stable interface), in a subprocess.

`lab up` does not hold the reservation itself: a keeper process does (`python -m
ktcs_bench.lab.labgrid keep ...`, `keep`), one per place, in a session of its own. The keeper
acquires the place (waiting while someone else holds it, with `--wait-for-place`), tells `lab up`
the serial port's URL on one JSON line, then blocks reading its standard input -- a pipe whose
only writer is `lab up` -- and releases the place when that pipe closes. The kernel closes it
however `lab up` ends: `lab down`, Ctrl-C, an exception, SIGKILL. In its own session, a Ctrl-C at
the terminal or a kill of `lab up`'s process group does not end the keeper before it releases.

The words labgrid-client answers with (`failure`) and its `env` output (`serial_url`) are read by
plain functions, checked without labgrid.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import yaml

from ktcs_bench.errors import PeerError, UsageError

if TYPE_CHECKING:
    from ktcs_bench.lab.topology import Lab

CLIENT = "labgrid-client"
CLIENT_TIMEOUT = 60.0
"""The longest one labgrid-client command may take (a coordinator that accepts but never answers)."""
RETRY_EVERY = 1.0
"""How often a keeper asks again for a place someone else holds (`--wait-for-place`)."""
PORT_TIMEOUT = 30.0
"""How long an acquired place's exporter may take to serve its serial port (it starts ser2net)."""
RELEASE_TRIES = 5
INSTALL = "pip install 'ktcs-bench[labgrid]' (make setup installs it)"

_HELD = re.compile(r"already acquired by (?P<holder>\S+?)\.?(?:\s|$)")
_HELD_BY_US = re.compile(
    r"You have already acquired place (?P<place>\S+?)(?: on (?P<host>\S+?))?\."
)
_UNREACHABLE = ("Could not connect to coordinator", "coordinator is unavailable")
_NO_PLACE = re.compile(r"place pattern \S+ matches nothing|place \S+ not found|matches nothing")


LABGRID_PORT = 20408
"""A labgrid coordinator's port, when its address gives none (labgrid's own default)."""


@dataclass(frozen=True)
class LabgridPlace:
    """A lab file's `external: {labgrid: PLACE, coordinator: HOST:PORT, resource: NAME}`: the
    place `lab up` acquires through the `coordinator` (None: labgrid's own default,
    LG_COORDINATOR or 127.0.0.1:20408) and whose exported serial port it opens (`resource`: which
    one, when the place has several)."""

    place: str
    coordinator: str | None = None
    resource: str | None = None


class PlaceHeld(PeerError):
    """A labgrid place someone else holds (`holder`: labgrid's HOST/USER of whoever acquired it)."""

    def __init__(self, place: str, holder: str, where: str, waited: float | None = None) -> None:
        self.place, self.holder = place, holder
        if waited is None:
            then = "`lab up --wait-for-place` waits until it is released, or ask"
        else:
            then = f"still, after waiting {waited:g} s (--place-timeout); ask"
        super().__init__(f"labgrid place {place} is held by {holder} (coordinator {where}); "
                         f"{then} {holder} to release it (labgrid-client -p {place} release)")  # fmt: skip


class LabgridMissing(UsageError):
    """labgrid's client is not installed where `lab up` looks for it."""


def coordinator_of(place: LabgridPlace) -> str:
    """Where the place's coordinator is, in words: the lab file's, else labgrid's own default."""
    return place.coordinator or os.environ.get("LG_COORDINATOR") or "127.0.0.1:20408"


def client_path() -> str:
    """labgrid-client: beside this Python (its venv), else on PATH."""
    beside = Path(sys.executable).parent / CLIENT
    if beside.is_file() and os.access(beside, os.X_OK):
        return str(beside)
    found = shutil.which(CLIENT)
    if found is None:
        raise LabgridMissing(f"a lab-file device names a labgrid place, and {CLIENT} is not "
                             f"installed: {INSTALL}")  # fmt: skip
    return found


def client_argv(place: LabgridPlace, *args: str) -> list[str]:
    """The labgrid-client command for `args` on the place (its coordinator, if the lab file gives
    one; else labgrid's own default, LG_COORDINATOR or 127.0.0.1:20408)."""
    where = ["-x", place.coordinator] if place.coordinator else []
    return [client_path(), *where, "-p", place.place, *args]


def failure(place: LabgridPlace, stderr: str, what: str) -> PeerError:
    """What labgrid-client's error output says, as one typed error naming the place: held by
    someone (`PlaceHeld`), a coordinator that cannot be reached, a place it does not know."""
    where = coordinator_of(place)
    held = _HELD.search(stderr)
    if held:
        return PlaceHeld(place.place, held.group("holder"), where)
    ours = _HELD_BY_US.search(stderr)
    if ours:  # the same host and user: another lab up, or the engineer's own acquire
        host = f" on {ours.group('host')}" if ours.group("host") else ""
        return PlaceHeld(place.place, f"you{host} (another lab up, or a labgrid-client acquire)",
                         where)  # fmt: skip
    if any(words in stderr for words in _UNREACHABLE):
        return PeerError(f"labgrid coordinator {where} cannot be reached (place {place.place}): "
                         "is labgrid-coordinator running there? (lab file: external.coordinator, "
                         "or LG_COORDINATOR)")  # fmt: skip
    if _NO_PLACE.search(stderr):
        return PeerError(f"labgrid coordinator {where} has no place {place.place} "
                         f"(labgrid-client places lists them)")  # fmt: skip
    said = [ln.strip() for ln in stderr.splitlines() if ln.strip() and "Traceback" not in ln]
    last = said[-1] if said else "no message"
    return PeerError(f"labgrid place {place.place} ({where}): {what} failed: {last}")


def serial_url(env_text: str, place: LabgridPlace) -> str | None:
    """The acquired place's serial port as a pyserial URL, from `labgrid-client env` (a labgrid
    environment: targets -> PLACE -> resources, each {CLASS: {name, host, port, ...}}); None
    while its exporter has not served it yet (no port). RFC 2217 as labgrid's own serial driver
    opens it: `ign_set_control`, since a port behind ser2net may have no modem lines to ack."""
    try:
        env = yaml.safe_load(env_text)
        targets = env["targets"]
        target = targets.get(place.place) or next(iter(targets.values()))
        resources = target.get("resources") or []
        if not isinstance(resources, list):
            raise TypeError("resources is not a list")
    except (yaml.YAMLError, ValueError, TypeError, LookupError, AttributeError, StopIteration,
            RecursionError):  # fmt: skip
        raise PeerError(f"labgrid place {place.place}: labgrid-client env gave no environment "
                        f"to read ({env_text[:200]!r})") from None  # fmt: skip
    ports: list[tuple[str, dict[str, object]]] = []
    for entry in resources:
        if isinstance(entry, dict) and isinstance(entry.get("NetworkSerialPort"), dict):
            args = entry["NetworkSerialPort"]
            ports.append((str(args.get("name", "NetworkSerialPort")), args))
    if place.resource is not None:
        ports = [p for p in ports if p[0] == place.resource]
    if len(ports) != 1:
        names = ", ".join(sorted(n for n, _ in ports)) if ports else "none"
        which = f" named {place.resource}" if place.resource else ""
        hint = "" if len(ports) < 2 else " (say which with external.resource)"
        raise PeerError(f"labgrid place {place.place} has {len(ports)} serial ports{which} "
                        f"(NetworkSerialPort: {names}); the lab needs one{hint}")  # fmt: skip
    args = ports[0][1]
    if not args.get("port") or not args.get("host"):
        return None
    host = str(args["host"])
    host = f"[{host}]" if ":" in host else host
    if args.get("protocol", "rfc2217") == "raw":
        return f"socket://{host}:{args['port']}"
    return f"rfc2217://{host}:{args['port']}?ign_set_control"


# -- the keeper: one process per place, holding it for as long as lab up lives ------------------


def _say(obj: dict[str, object]) -> None:
    """One JSON line to lab up (gone already: nothing to tell, the place is released anyway)."""
    try:
        print(json.dumps(obj), flush=True)
    except (BrokenPipeError, ValueError):
        pass


def _closed_within(seconds: float) -> bool:
    """Whether lab up's pipe (our standard input) closes within `seconds`: lab up has ended."""
    ready, _, _ = select.select([sys.stdin.fileno()], [], [], max(0.0, seconds))
    return bool(ready) and os.read(sys.stdin.fileno(), 4096) == b""


def _run(place: LabgridPlace, *args: str) -> subprocess.CompletedProcess[str]:
    try:
        return subprocess.run(client_argv(place, *args), capture_output=True, text=True,
                              timeout=CLIENT_TIMEOUT, stdin=subprocess.DEVNULL)  # fmt: skip
    except subprocess.TimeoutExpired:
        return subprocess.CompletedProcess([], 1, "", f"Could not connect to coordinator "
                                           f"(no answer within {CLIENT_TIMEOUT:g} s)")  # fmt: skip


def keep(place: LabgridPlace, wait: float | None) -> int:
    """Acquire the place (waiting up to `wait` seconds while someone else holds it; None: not at
    all; inf: until lab up ends), tell lab up its serial port's URL, hold it until lab up's pipe
    closes, release it. Exit 0, or 1 after telling lab up why it could not."""

    def on_signal(signum: int, frame: object) -> None:  # SIGTERM, SIGHUP, SIGINT: release, end
        raise SystemExit(0)

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, on_signal)
    deadline = None if wait is None or math.isinf(wait) else time.monotonic() + wait
    told = ""
    maybe_ours = False  # from the moment an acquire is asked until it is known to have failed
    try:
        while True:
            maybe_ours = True
            done = _run(place, "acquire")
            if done.returncode == 0:
                break
            maybe_ours = False
            why = failure(place, done.stderr, "acquire")
            print(f"acquire: {done.stderr.strip()}", file=sys.stderr, flush=True)
            if not isinstance(why, PlaceHeld) or wait is None:
                _say({"error": str(why), "holder": getattr(why, "holder", None)})
                return 1
            if deadline is not None and time.monotonic() >= deadline:
                _say({"error": str(why), "holder": why.holder, "waited": wait})
                return 1
            if why.holder != told:
                _say({"waiting": why.holder})
                told = why.holder
            if _closed_within(RETRY_EVERY):
                return 0  # lab up ended while it waited: nothing acquired, nothing to release
        end = time.monotonic() + PORT_TIMEOUT
        url = None
        while url is None:
            env = _run(place, "env")
            if env.returncode != 0:
                raise failure(place, env.stderr, "env")
            url = serial_url(env.stdout, place)
            if url is None:
                if time.monotonic() >= end:
                    raise PeerError(f"labgrid place {place.place}: its exporter serves no serial "
                                    f"port within {PORT_TIMEOUT:g} s of the acquire")  # fmt: skip
                if _closed_within(0.2):
                    return 0
        print(f"acquired {place.place}: {url}", file=sys.stderr, flush=True)
        _say({"acquired": place.place, "url": url})
        while os.read(sys.stdin.fileno(), 4096):  # until lab up's end closes the pipe
            pass
        return 0
    except PeerError as exc:
        _say({"error": str(exc), "holder": None})
        return 1
    finally:
        for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
            signal.signal(sig, signal.SIG_IGN)  # the release is not cut short
        if maybe_ours:
            _release(place)


def _release(place: LabgridPlace) -> None:
    for _ in range(RELEASE_TRIES):
        done = _run(place, "release")
        if done.returncode == 0:
            print(f"released {place.place}", file=sys.stderr, flush=True)
            return
        print(f"release: {done.stderr.strip()}", file=sys.stderr, flush=True)
        if "not acquired" in done.stderr or "acquired by a different user" in done.stderr:
            return  # not ours any more (released, or taken by force): nothing to give back
        time.sleep(RETRY_EVERY)  # a coordinator briefly away: ask again


def main(argv: list[str] | None = None) -> int:
    """`python -m ktcs_bench.lab.labgrid keep --place P [--coordinator C] [--resource R]
    [--wait SECONDS|inf]`: the keeper `Places` starts."""
    parser = argparse.ArgumentParser(prog="python -m ktcs_bench.lab.labgrid")
    parser.add_argument("action", choices=["keep"])
    parser.add_argument("--place", required=True)
    parser.add_argument("--coordinator")
    parser.add_argument("--resource")
    parser.add_argument("--wait", type=float, help="seconds to wait for a held place (inf: no end)")
    args = parser.parse_args(argv)
    try:
        return keep(LabgridPlace(args.place, args.coordinator, args.resource), args.wait)
    except UsageError as exc:  # labgrid-client missing
        _say({"error": str(exc), "holder": None, "usage": True})
        return 1


# -- lab up's side ---------------------------------------------------------------------------------


@dataclass
class Keeper:
    device: str
    place: LabgridPlace
    proc: subprocess.Popen[str]


class Places:
    """The labgrid places of a lab, each held by a keeper process for as long as this lab lives.
    `wait`: how long to wait for a place someone else holds (None: not at all, a `PlaceHeld`
    error; inf: until `lab up` is stopped). `say`: where the waiting is told."""

    def __init__(
        self, log_dir: Path, wait: float | None = None, say: Callable[[str], None] | None = None
    ) -> None:
        self.log_dir, self.wait = log_dir, wait
        self.say = say or (lambda text: print(text, file=sys.stderr, flush=True))
        self.keepers: list[Keeper] = []

    async def acquire(self, lab: Lab, stop: asyncio.Event) -> Lab:
        """The lab with every labgrid place acquired and its device's `serial` set to the place's
        port; the lab as it is when it names none. Stopped (`stop` set) while it waits: the lab
        as it is, the keepers told to give up. A place that cannot be had: PeerError (PlaceHeld
        for one someone else holds), UsageError without labgrid."""
        wanted = {n: d.external.labgrid for n, d in lab.devices.items()
                  if d.external is not None and d.external.labgrid is not None}  # fmt: skip
        if not wanted:
            return lab
        client_path()  # labgrid missing: said before any keeper starts
        for name, place in wanted.items():
            self.keepers.append(Keeper(name, place, self._start(name, place)))
        reading = [asyncio.ensure_future(asyncio.to_thread(self._url, k)) for k in self.keepers]
        for task in reading:  # a reader left behind (stopped, another place failed) ends quietly
            task.add_done_callback(lambda t: t.cancelled() or t.exception())
        stopped = asyncio.ensure_future(stop.wait())
        try:
            pending: set[asyncio.Future[Any]] = set(reading)
            while pending:
                done, _ = await asyncio.wait(
                    {*pending, stopped}, return_when=asyncio.FIRST_COMPLETED
                )
                if stopped in done:
                    return lab
                for finished in done:
                    pending.discard(finished)
                    finished.result()  # a place that could not be had ends the start here
        finally:
            stopped.cancel()
        urls = {k.device: r.result() for k, r in zip(self.keepers, reading, strict=True)}
        devices = dict(lab.devices)
        for name, url in urls.items():
            d = devices[name]
            assert d.external is not None
            devices[name] = replace(d, external=replace(d.external, serial=url))
        return replace(lab, devices=devices)

    def _start(self, device: str, place: LabgridPlace) -> subprocess.Popen[str]:
        argv = [sys.executable, "-m", "ktcs_bench.lab.labgrid", "keep", "--place", place.place]
        argv += ["--coordinator", place.coordinator] if place.coordinator else []
        argv += ["--resource", place.resource] if place.resource else []
        argv += ["--wait", str(self.wait)] if self.wait is not None else []
        log: IO[str] = open(self.log_dir / f"labgrid-{device}.log", "a")  # noqa: SIM115
        try:
            # its own session: neither a Ctrl-C at the terminal nor a kill of lab up's process
            # group ends it before it has released; its stdin's only writer is this process
            return subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    stderr=log, text=True, start_new_session=True)  # fmt: skip
        finally:
            log.close()

    def _url(self, keeper: Keeper) -> str:
        """The keeper's answer: the place's serial URL, or the error it gives (a thread: it may
        wait as long as someone else holds the place)."""
        assert keeper.proc.stdout is not None
        for line in keeper.proc.stdout:
            try:
                said = json.loads(line)
            except ValueError:
                continue  # not the keeper's word (it says all it has to say as JSON)
            if "waiting" in said:
                self.say(f"lab: {keeper.device}'s labgrid place {keeper.place.place} is held by "
                         f"{said['waiting']}; waiting until it is released (Ctrl-C gives up)")  # fmt: skip
            elif "acquired" in said:
                return str(said["url"])
            elif "error" in said:
                if said.get("usage"):
                    raise LabgridMissing(str(said["error"]))
                if said.get("holder"):
                    raise PlaceHeld(keeper.place.place, str(said["holder"]),
                                    coordinator_of(keeper.place), said.get("waited"))  # fmt: skip
                raise PeerError(str(said["error"]))
        if keeper.proc.stdin is None or keeper.proc.stdin.closed:
            return ""  # given up: the lab is stopping
        log = self.log_dir / f"labgrid-{keeper.device}.log"
        raise PeerError(f"the keeper of labgrid place {keeper.place.place} ended without "
                        f"acquiring it (exit {keeper.proc.wait()}; {log})")  # fmt: skip

    def release(self, timeout: float = 30.0) -> list[str]:
        """Give every place back: each keeper's pipe closed, it releases and ends. What could
        not be confirmed, in words (a keeper still releasing after `timeout` goes on alone)."""
        problems = []
        for k in self.keepers:
            if k.proc.stdin is not None and not k.proc.stdin.closed:
                k.proc.stdin.close()
        for k in self.keepers:
            try:
                k.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                problems.append(f"labgrid place {k.place.place} is still being released "
                                f"(keeper pid {k.proc.pid})")  # fmt: skip
        self.keepers = []
        return problems


if __name__ == "__main__":
    sys.exit(main())
