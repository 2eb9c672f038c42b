"""Why the IXL refused a control: the reason numbers of Type II CONTROL_RESULT (SPEC §4).

The numbers are wire values and must match `protocols/type2.yaml`; this enum is the one place the
interlocking spells them.
"""

from __future__ import annotations

from enum import IntEnum


class Reason(IntEnum):
    NONE = 0
    NOT_IN_CENTER_MODE = 1  # (for a local-panel control: the station is in center mode)
    ROUTE_CONFLICTS = 2
    TRACK_OCCUPIED = 3
    POINT_LOCKED = 4
    POINT_FAILED = 5
    UNKNOWN_CODE = 6
    DIRECTION = 7  # a departure into an interval whose traffic permission this end lacks

    @property
    def text(self) -> str:
        return self.name.lower().replace("_", " ")
