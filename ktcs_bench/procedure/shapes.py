"""The shape of a procedure file's top level and its setup, declared once (msgspec Structs,
`schema.Shape`): its keys, their types and defaults. `model.load_procedure` converts a file with
`schema.convert` in `YamlReader`'s words, then checks what hangs on the lab (stations, track
circuits, devices, trains). The words of each step -- the step grammar -- stay in `steps`."""

from __future__ import annotations

from typing import Annotated, Any

import msgspec
from msgspec import Meta

from ktcs_bench.schema import Shape

Text = str | int
"""A name or a word; a number is taken as its digits."""
Texts = Text | tuple[Text, ...]
"""One text or a list of them (`tags: route` or `tags: [route, ctc]`)."""


class TrainShape(Shape):
    """A train of `setup.trains:` the procedure places and moves itself."""

    id: Text
    head: Text  # metres along the line, or a track circuit whose middle it stands on
    length_m: Annotated[float, Meta(ge=1.0)] = 40.0
    track: Text = "1"


class SetupShape(Shape):
    """`setup:` -- the lab, and what is brought about before the first step."""

    lab: Text = "reference"  # a lab of emulators/labs/, or a lab file beside the procedure
    trains: tuple[TrainShape, ...] = ()
    modes: dict[Any, Any] = {}  # STATION -> center | local: both checked against the lab
    ars: bool | None = None  # None: as the lab has it
    restart: tuple[Text, ...] = ()  # devices restarted first


class ProcedureShape(Shape):
    """The procedure file. `steps` is a list of mappings whose words `steps.parse_step` reads."""

    id: Text | msgspec.UnsetType = msgspec.UNSET  # unset: the file's name
    title: Text | msgspec.UnsetType = msgspec.UNSET  # unset: the file's name
    verifies: Texts = ()
    tags: Texts = ()
    always: tuple[Text, ...] = ()  # expectations that hold at every sample of the run
    setup: SetupShape = msgspec.field(default_factory=SetupShape)
    steps: list[Any] | None = None  # at least one: checked in code
