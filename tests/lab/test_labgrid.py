"""Issue 26: a real device a test team shares, reserved through labgrid (SPEC §10). The live
test stands a real labgrid coordinator up on the lab's host and a labgrid exporter on another
host (a network namespace) exporting an emulated ATC's pty, which the exporter serves with
ser2net over RFC 2217; what runs there, and what is checked, is `labgrid_hosts.py`. The others
check the lab file's keys and the reading of labgrid's answers, without a coordinator.

Never skipped: labgrid is in the test extra (`make setup`), ser2net, util-linux and iproute2 in
`.ci/system-deps`; a machine without them fails here, saying so."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from ktcs_bench.errors import ConfigError, PeerError
from ktcs_bench.lab.labgrid import LabgridPlace, PlaceHeld, failure, serial_url
from ktcs_bench.lab.topology import load_lab
from tests.lab.netns import require_namespaces, run_driver

TIMEOUT = 240.0
LINE = Path(__file__).resolve().parents[2] / "emulators" / "lines" / "reference.yaml"
TOOLS = ("labgrid-client", "labgrid-coordinator", "labgrid-exporter")


def require_labgrid() -> None:
    missing = [t for t in TOOLS if not (Path(sys.executable).parent / t).is_file()]
    if missing:
        pytest.fail(f"{', '.join(missing)} not beside {sys.executable}: labgrid is in the test "
                    "extra (`make setup` installs it); this test needs it and is not skipped")  # fmt: skip


def test_a_shared_atc_reserved_through_labgrid_on_another_host(tmp_path: Path) -> None:
    require_labgrid()
    require_namespaces(("ser2net",))
    seen = run_driver("tests.lab.labgrid_hosts", tmp_path, TIMEOUT)
    assert "held by bench2/alice" in seen["held"], seen
    report = seen["procedure"]
    assert report.startswith("PASS  labgrid-atc18"), report
    frames = [ln for ln in report.splitlines() if "frame st18-atc" in ln]  # both ways, via labgrid
    assert len(frames) == 2 and all(" pass " in ln for ln in frames), report
    assert seen["after_down"] is None and seen["after_sigint"] is None, seen
    assert seen["after_sigkill"] is None, seen


def write_lab(tmp: Path, external: str) -> Path:
    path = tmp / "lg.yaml"
    path.write_text(
        f"lab: lg\nline: {LINE}\ndevices:\n  ixl18: {{kind: ixl, station: 18}}\n"
        f"  atc18: {{kind: atc, station: 18, external: {external}}}\n"
        "links:\n  - {name: st18-atc, type: type1, a: ixl18, b: atc18}\n",
        encoding="utf-8",
    )
    return path


def test_a_labgrid_entry_names_the_place_its_coordinator_and_resource(tmp_path: Path) -> None:
    lab = load_lab(write_lab(tmp_path, "{labgrid: rack2-atc, coordinator: lg.lab, resource: atc}"))
    ext = lab.devices["atc18"].external
    assert ext is not None and ext.serial is None
    assert ext.labgrid == LabgridPlace("rack2-atc", "lg.lab:20408", "atc")
    assert ext.endpoint == "labgrid place rack2-atc"  # until lab up acquires it
    bare = load_lab(write_lab(tmp_path, "{labgrid: rack2-atc}")).devices["atc18"].external
    assert bare is not None and bare.labgrid == LabgridPlace("rack2-atc")


@pytest.mark.parametrize(
    ("external", "place", "words"),
    [
        ("{labgrid: a, serial: /dev/ttyS0}", "devices.atc18.external.labgrid", "not both"),
        ("{serial: /dev/ttyS0, coordinator: 'h:1'}", "devices.atc18.external.coordinator",
         "goes with a labgrid place"),
        ("{labgrid: a, coordinator: 'h:99999'}", "devices.atc18.external.coordinator",
         "out of range"),
        ("{labgrid: ' a'}", "devices.atc18.external.labgrid", "without spaces"),
        ("{labgrid: 3}", "devices.atc18.external.labgrid", "string"),
        ("{labgrid: a, place: b}", "devices.atc18.external.place", "unknown key"),
        ("{}", "devices.atc18.external.serial", "labgrid place"),
    ],
)  # fmt: skip
def test_a_bad_labgrid_entry_is_one_error_naming_the_key(
    tmp_path: Path, external: str, place: str, words: str
) -> None:
    with pytest.raises(ConfigError) as err:
        load_lab(write_lab(tmp_path, external))
    assert err.value.place == place and words in err.value.problem, str(err.value)


ENV = """\
targets:
  atc18:
    resources:
    - NetworkSerialPort:
        name: RawSerialPort
        speed: 9600
        host: 10.99.0.2
        port: 41657
"""


def test_the_acquired_places_serial_port_is_read_from_labgrid_env() -> None:
    place = LabgridPlace("atc18")
    assert serial_url(ENV, place) == "rfc2217://10.99.0.2:41657?ign_set_control"
    assert serial_url(ENV.replace("41657", "null"), place) is None  # ser2net not serving yet
    raw = ENV + "        protocol: raw\n"
    assert serial_url(raw, place) == "socket://10.99.0.2:41657"
    two = ENV + ENV.split("resources:\n", 1)[1].replace("RawSerialPort", "io").replace("41657", "5")
    with pytest.raises(PeerError, match="2 serial ports.*external.resource"):
        serial_url(two, place)
    assert serial_url(two, LabgridPlace("atc18", resource="io")) == (
        "rfc2217://10.99.0.2:5?ign_set_control"
    )
    with pytest.raises(PeerError, match="no environment"):
        serial_url("labgrid-client: nothing", place)


YAML_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.text(max_size=12),
    lambda inner: (
        st.lists(inner, max_size=3)
        | st.dictionaries(
            st.sampled_from(
                [
                    "targets",
                    "atc18",
                    "resources",
                    "NetworkSerialPort",
                    "name",
                    "host",
                    "port",
                    "protocol",
                    "x",
                ]
            ),
            inner,
            max_size=4,
        )
    ),  # fmt: skip
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.text(max_size=80), YAML_VALUES.map(yaml.safe_dump)))
def test_whatever_labgrid_env_prints_is_a_url_nothing_yet_or_a_peer_error(text: str) -> None:
    """labgrid-client's output is another program's: any text, or any YAML shaped near an
    environment, gives a URL, None (not served yet) or one PeerError -- never a traceback."""
    try:
        url = serial_url(text, LabgridPlace("atc18"))
    except PeerError:
        return
    assert url is None or url.startswith(("rfc2217://", "socket://"))


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_whatever_labgrid_client_says_on_failure_is_one_peer_error(stderr: str) -> None:
    assert isinstance(failure(LabgridPlace("atc18"), stderr, "acquire"), PeerError)


def test_labgrids_refusals_become_typed_errors_naming_place_and_holder() -> None:
    place = LabgridPlace("atc18", "10.0.0.9:20408")
    held = failure(place, "labgrid-client: Error: Place atc18 is already acquired by bench2/alice. "
                   "To work simultaneously, alice can execute ...", "acquire")  # fmt: skip
    assert isinstance(held, PlaceHeld) and held.holder == "bench2/alice"
    assert "held by bench2/alice (coordinator 10.0.0.9:20408)" in str(held)
    ours = failure(place, "labgrid-client: Error: You have already acquired place atc18.", "x")
    assert isinstance(ours, PlaceHeld) and ours.holder.startswith("you (another lab up")
    gone = failure(place, "ERROR root: coordinator is unavailable: failed to connect\n"
                   "Server error: Error: Could not connect to coordinator", "acquire")  # fmt: skip
    assert not isinstance(gone, PlaceHeld) and "10.0.0.9:20408 cannot be reached" in str(gone)
    unknown = failure(place, "labgrid-client: Error: place pattern atc18 matches nothing", "a")
    assert "has no place atc18" in str(unknown)


def test_a_coordinator_that_cannot_be_reached_is_exit_3_in_words(tmp_path: Path) -> None:
    require_labgrid()
    path = write_lab(tmp_path, "{labgrid: atc18, coordinator: '127.0.0.1:1'}")
    done = subprocess.run([sys.executable, "-m", "ktcs_bench.cli.main", "lab", "up", str(path),
                           "--for", "5"], capture_output=True, text=True, timeout=60,
                          env={**__import__("os").environ,
                               "KTCS_BENCH_RUN_DIR": str(tmp_path / "run")})  # fmt: skip
    assert done.returncode == 3, done.stderr
    assert "labgrid coordinator 127.0.0.1:1 cannot be reached (place atc18)" in done.stderr
    assert "Traceback" not in done.stderr


def test_labgrids_pytest_plugin_stays_out_of_our_runs(pytestconfig: pytest.Config) -> None:
    """labgrid registers a pytest plugin (an entry point) that would rewire our logging and
    read LG_ENV: pyproject's addopts block it (-p no:labgrid)."""
    assert pytestconfig.pluginmanager.is_blocked("labgrid")
    assert not pytestconfig.pluginmanager.has_plugin("labgrid")
