"""A core's side of one link: its codes by name one way, the link's code numbers the other.

`LinkBinding(tx, rx, state)` holds the chart the core sends (`tx`), the chart it reads (`rx`) --
a station device's pair is `station_codes.link_charts(view, link)` -- and where the core's state
of the tx codes is read (`state()`: the core's own table, so there is one).
Out: `send(changes)` takes the core's code changes -- already the one difference against what was
sent, which the core works out -- and returns them as (number, state) items; while the link is
down nothing is returned and what changed is owed: `link_up()` returns it, `link_down()` owes
everything (what was queued was lost, and the peer may not have noticed the outage).
`full_state()` and `statuses()` are the whole tx chart, for a full-state dump or ALL_INFO.
In: `received(items)` and `received_all(statuses)` turn the peer's numbers into names (and say
which numbers the chart lacks); a control the peer sends is named by `control_name`.

`ControlLink` is a link whose peer sends controls, each answered (the IXL's Type II side): it is
the application the Type II client serves (`full_state`, `on_control`), answering a number the
chart lacks itself and handing every other control to the core by name. A control the core
answers later (a departure waiting for an interval's permission, SPEC §6.6) is answered None
now; its answer is numbered by `control_number` when it comes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence

from ktcs_bench.station_codes.chart import CodeChart

StateOf = Callable[[], Mapping[str, int]]


class LinkBinding:
    """One link of a core. See the module docstring."""

    def __init__(self, tx: CodeChart, rx: CodeChart, state: StateOf, *, up: bool = False) -> None:
        self.tx, self.rx = tx, rx
        self.state = state
        self.up = up
        self._owed: set[str] = set()

    # ------------------------------------------------------------------ out

    def send(self, changes: Iterable[tuple[str, int]]) -> list[tuple[int, int]]:
        """The core's changes as (number, state) items to send now (none while the link is down:
        they are owed). A name the tx chart lacks is not carried."""
        items: list[tuple[int, int]] = []
        for name, value in changes:
            if name not in self.tx:
                continue
            if self.up:
                items.append((self.tx.number_of(name), int(value)))
            else:
                self._owed.add(name)
        return items

    def link_up(self) -> list[tuple[int, int]]:
        """The link is up: what is owed, as items to send now."""
        self.up = True
        owed, self._owed = self._owed, set()
        state = self.state()
        return [(self.tx.number_of(n), int(state.get(n, 0))) for n in sorted(owed)]

    def link_down(self) -> None:
        """The link is down: everything is owed when it is back."""
        self.up = False
        self._owed.update(self.tx.names)

    def sent(self) -> dict[str, int]:
        """Every tx code's state by name, as the link carries it."""
        state = self.state()
        return {name: int(state.get(name, 0)) for name in self.tx.names}

    def full_state(self) -> list[tuple[int, int]]:
        """Every tx code as (number, state), in chart order: a full-state dump."""
        state = self.state()
        return [(c.number, int(state.get(c.name, 0))) for c in self.tx.codes]

    def statuses(self) -> list[int]:
        """Every tx code's state, in chart order (ALL_INFO: byte k-1 is code k)."""
        return list(self.sent().values())

    # ------------------------------------------------------------------ in

    def received(self, items: Iterable[Sequence[int]]) -> tuple[dict[str, int], list[int]]:
        """(number, state) items from the peer as {name: state}, and the numbers the rx chart
        lacks (left out)."""
        out: dict[str, int] = {}
        unknown: list[int] = []
        for number, value in items:
            name = self.rx.name_of(number)
            if name is None:
                unknown.append(number)
            else:
                out[name] = value
        return out, unknown

    def received_all(self, statuses: Sequence[int]) -> dict[str, int]:
        """A full state from the peer (byte k-1 is code k) as {name: state}."""
        return {c.name: statuses[c.number - 1] for c in self.rx.codes if c.number <= len(statuses)}

    def control_name(self, number: int) -> str | None:
        """The name of control `number`, or None when the rx chart has no such code."""
        return self.rx.name_of(number)


class ControlLink(LinkBinding):
    """A link whose peer sends controls, each answered (accepted, reason): the Type II
    application of the IXL. `control(name, value)` is the core's answer (None: it comes later);
    `unknown_reason` the
    reason number for a control the chart lacks, `on_unknown(number, value)` told of one."""

    def __init__(
        self,
        tx: CodeChart,
        rx: CodeChart,
        state: StateOf,
        control: Callable[[str, int], tuple[bool, int] | None],
        unknown_reason: int,
        on_unknown: Callable[[int, int], None] | None = None,
    ) -> None:
        # a Type II link is never owed changes: every connection starts with a full state
        super().__init__(tx, rx, state, up=True)
        self.control = control
        self.unknown_reason = unknown_reason
        self.on_unknown = on_unknown

    def on_control(self, code: int, value: int) -> tuple[bool, int] | None:
        """One CONTROL item (number, value) -> (accepted, reason); None: answered later."""
        name = self.control_name(code)
        if name is None:
            if self.on_unknown is not None:
                self.on_unknown(code, value)
            return False, self.unknown_reason
        return self.control(name, value)

    def control_number(self, name: str) -> int:
        """The number of control `name` (a late answer is sent by it)."""
        return self.rx.number_of(name)
