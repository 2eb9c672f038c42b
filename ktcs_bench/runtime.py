"""The runtime folder of the user who runs the bench, and the identity of the processes in it.

The folder is $KTCS_BENCH_RUN_DIR, else $XDG_RUNTIME_DIR/ktcs-bench, else
/tmp/ktcs-bench-<uid>. Labs keep their state there (`labs/NAME/lab.json`, logs, captures, the
lab's token), named taps announce themselves there (`taps/NAME.json`). It is made 0700; one that
another user owns is refused (it could hold a token planted for us).

A process is named by its pid and its start time (clock ticks since boot, /proc/PID/stat): pids
are reused, so a pid alone left in a state file by a process that died may name a stranger.

Who may operate what runs here: every control port (a device's, a lab's, a tap's) obeys only a
client that presents its token, a random secret kept in a file only its owner can read (0600).
A lab's token is `labs/NAME/token`; a device or tap started on its own uses the user's token,
`token` in the run folder, unless `--token-file` (or $KTCS_BENCH_TOKEN_FILE) names another -- the
way to operate from another computer is to copy the token file there and name it so. A client
finds the token by the address it talks to (the labs and taps announced here say which token file
is theirs), else $KTCS_BENCH_TOKEN_FILE, else the user's token.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import stat
import tempfile
from pathlib import Path
from typing import Any

from ktcs_bench.errors import UsageError


def run_dir() -> Path:
    if "KTCS_BENCH_RUN_DIR" in os.environ:
        return Path(os.environ["KTCS_BENCH_RUN_DIR"])
    if "XDG_RUNTIME_DIR" in os.environ:
        return Path(os.environ["XDG_RUNTIME_DIR"]) / "ktcs-bench"
    return Path(tempfile.gettempdir()) / f"ktcs-bench-{os.getuid()}"


def private_dir(path: Path) -> Path:
    """`path` made (0700) if missing; a UsageError if it is not a folder of ours that only we
    may write. Its parents are made as needed (the run folder itself included)."""
    root = run_dir()
    root.mkdir(mode=0o700, parents=True, exist_ok=True)
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    for p in (root, path):
        st = p.lstat()
        if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
            raise UsageError(f"{p} is not a folder of user {os.getuid()}: refusing to use it")
        if st.st_mode & 0o022:
            raise UsageError(f"{p} may be written by others (mode {st.st_mode & 0o777:o})")
    return path


def process_started(pid: int) -> int | None:
    """The start time of process `pid` (clock ticks since boot), None if there is no such live
    process (a zombie counts as gone)."""
    if pid <= 0:
        return None
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rpartition(")")[2].split()  # after "pid (comm)": state is field 3
    if len(fields) < 20 or fields[0] in ("Z", "X"):
        return None
    return int(fields[19])  # field 22, starttime


def process_alive(pid: int, started: int | None = None) -> bool:
    """Process `pid` runs, and is the one that started at `started` (when given)."""
    now = process_started(pid)
    return now is not None and (started is None or now == started)


def this_process() -> dict[str, Any]:
    """{"pid", "started"} of the calling process, for a state file."""
    return {"pid": os.getpid(), "started": process_started(os.getpid())}


TOKEN_ENV = "KTCS_BENCH_TOKEN_FILE"
_TOKEN = re.compile(r"[0-9a-f]{32,128}")


def user_token_file() -> Path:
    return run_dir() / "token"


def read_token(path: Path) -> str:
    """The token in `path`; a UsageError if the file is missing, not ours, readable by others or
    holds no token."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError as exc:
        raise UsageError(f"token file {path}: {exc.strerror}") from None
    with os.fdopen(fd, encoding="ascii", errors="replace") as f:
        st = os.fstat(f.fileno())
        if st.st_uid != os.getuid():
            raise UsageError(f"token file {path} belongs to another user: refusing it")
        if st.st_mode & 0o077:
            raise UsageError(
                f"token file {path} may be read by others (mode {st.st_mode & 0o777:o}); "
                f"`chmod 600 {path}`"
            )
        token = f.read(256).strip()
    if not _TOKEN.fullmatch(token):
        raise UsageError(f"token file {path} holds no token (64 hex digits)")
    return token


def ensure_token(path: Path) -> str:
    """The token kept in `path`, made first if there is none: 32 random bytes in hex, in a file
    of mode 0600 put in place whole (a reader never sees it half written)."""
    if not path.exists():
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
        except OSError as exc:
            raise UsageError(f"cannot make token file {path}: {exc.strerror}") from None
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(secrets.token_hex(32) + "\n")
        try:
            os.link(tmp, path)  # fails if another process made it meanwhile: theirs stands
        except FileExistsError:
            pass
        finally:
            tmp.unlink()
    return read_token(path)


def server_token(path: str | Path | None = None) -> tuple[str, Path]:
    """The token a server requires and its file: `path`, else $KTCS_BENCH_TOKEN_FILE, else the
    user's token file (made, in a private run folder, when missing)."""
    if path is None and os.environ.get(TOKEN_ENV):
        path = os.environ[TOKEN_ENV]
    if path is None:
        private_dir(run_dir())
        path = user_token_file()
    file = Path(path)
    return ensure_token(file), file


def token_file_for(address: tuple[str, int], folder: Path | None = None) -> Path | None:
    """The token file of the lab or tap announced in the run folder (or `folder`) that serves
    `address`, if one does."""
    root = folder if folder is not None else run_dir()
    want = f"{address[0]}:{address[1]}"
    for path in [*root.glob("labs/*/lab.json"), *root.glob("taps/*.json")]:
        try:
            info = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if not isinstance(info, dict) or not info.get("token_file"):
            continue
        found = [info.get("control")]
        for d in (info.get("devices") or {}).values():
            found += [d.get("control"), d.get("listen")] if isinstance(d, dict) else []
        found += [e.get("tap") for e in info.get("links") or () if isinstance(e, dict)]
        found = [f"{a[0]}:{a[1]}" if isinstance(a, list) and len(a) == 2 else a for a in found]
        if want in found:
            return Path(info["token_file"])
    return None


def client_token(address: tuple[str, int] | None = None) -> str | None:
    """The token to present to `address`: from $KTCS_BENCH_TOKEN_FILE, else the token file of the
    lab or tap that serves it, else the user's token; None if there is none."""
    if os.environ.get(TOKEN_ENV):
        return read_token(Path(os.environ[TOKEN_ENV]))
    found = token_file_for(address) if address is not None else None
    if found is not None:
        return read_token(found)
    if user_token_file().exists():
        return read_token(user_token_file())
    return None


def token_matches(given: object, token: str) -> bool:
    return isinstance(given, str) and secrets.compare_digest(given.encode(), token.encode())
