"""`ctc direction ST INTERVAL` through the real CTC device, in one process with the reference
stations' real interlockings as its Type II clients over TCP on 127.0.0.1 (`console.demo.RigIxl`),
and `ktcs-bench ctc` in a real subprocess against its control port: the command goes out as the
station's DRC code, its CONTROL_RESULT comes back and is printed, the command log says it in the
operator's words, the exit code follows the answer, and `ctc show` prints each interval."""

from __future__ import annotations

import asyncio
import json
import os
import sys
from pathlib import Path

from ktcs_bench.console.demo import RigIxl
from ktcs_bench.emulator.ctc import CtcDevice
from ktcs_bench.ixl.modes import Mode
from ktcs_bench.messages import AskDirection, Show
from ktcs_bench.runtime import TOKEN_ENV, ensure_token

from .ars_rig import LINE

STATIONS = [18, 20, 22]


async def cli(token: Path, *args: str) -> tuple[int, str, str]:
    """`ktcs-bench ARGS` in a subprocess, presenting the token in file `token`."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "ktcs_bench.cli.main", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        env={**os.environ, TOKEN_ENV: str(token)},
    )  # fmt: skip
    out, err = await asyncio.wait_for(proc.communicate(), 60)
    assert proc.returncode is not None
    return proc.returncode, out.decode(), err.decode()


def test_ctc_direction_goes_out_as_drc_and_its_answer_comes_back(tmp_path: Path) -> None:
    token = tmp_path / "token"

    async def main() -> None:
        ctc = CtcDevice("ctc", LINE, STATIONS, ("127.0.0.1", 0))
        ctc.token = ensure_token(token)  # its control port asks for it, as in a lab
        await ctc.start()
        rigs = {st: RigIxl(LINE, st, mode=Mode.CENTER) for st in STATIONS}
        try:
            for rig in rigs.values():
                rig.start("127.0.0.1", ctc.server.port)
            await ctc.server.wait_until(
                lambda: all(t.known for t in ctc.model.tables.stations.values()), 10.0
            )
            answer = await ctc.handle(AskDirection(station=20, interval="1820"))
            assert getattr(answer, "code", None) == "DRC1820"
            assert isinstance(getattr(answer, "reason", None), int)  # the IXL answered
            entry = ctc.desk.log.last(1)[0]
            assert entry["command"] == "direction 20 1820" and entry["code"] == "DRC1820"
            assert entry["result"] == answer.result  # type: ignore[attr-defined]
            assert any(e["kind"] == "control" and "DRC1820=1" in e["text"] for e in ctc.events)

            port = ctc.ready_info["control"].rpartition(":")[2]
            code, out, err = await cli(token, "ctc", "--address", f"127.0.0.1:{port}", "--json",
                                       "direction", "20", "1820")  # fmt: skip
            said = json.loads(out.splitlines()[-1])
            assert said["command"] == "direction 20 1820" and said["code"] == "DRC1820", err
            assert code == (0 if said["ok"] else 1)
            # a lab-edge interval has no neighbour: refused by the CTC, nothing sent, exit 1
            code, out, _ = await cli(token, "ctc", "--address", f"127.0.0.1:{port}", "--no-colour",
                                     "direction", "18", "1618")  # fmt: skip
            assert code == 1 and "interval 1618 is at the lab's edge" in out
            # `ctc show` prints each interval of the station, read from both its ends
            code, out, _ = await cli(token, "ctc", "--address", f"127.0.0.1:{port}", "show", "20")
            assert code == 0
            lines = [ln.strip() for ln in out.splitlines() if ln.strip().startswith("interval")]
            assert [ln.split()[1] for ln in lines] == ["1820", "2022"]
            show = await ctc.handle(Show(station=20))
            shown = show.summary["intervals"]  # type: ignore[attr-defined]
            assert lines[0] == "interval " + shown["1820"]["text"]
            assert shown["1820"]["direction"] in ("up", "down", None)
        finally:
            for rig in rigs.values():
                await rig.close()
            await ctc.close()

    asyncio.run(main())
