"""The requirements catalogue (`emulators/requirements/ktcs.yaml`, or a user's own): an id, the
requirement in one sentence, its source and the roles it applies to. Every check names the ids
it verifies; `check_ids` refuses one the catalogue does not hold, before anything runs.

The file's shape is declared once (`CatalogueShape`, `schema.convert`); what a shape cannot say
-- an id's spelling, an id given twice, a role no device kind has -- is checked here, each
mistake one ConfigError naming the file, the key path and the line.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from msgspec import Meta

from ktcs_bench import kinds
from ktcs_bench.datafiles import data_dir, load_mapping
from ktcs_bench.errors import ConfigError, excerpt
from ktcs_bench.schema import Shape, convert, located

ID_PATTERN = re.compile(r"^[A-Z][A-Z0-9]*(-[A-Z0-9]+)*$")
"""An id as the catalogue spells it: upper-case words joined by hyphens (`IXL-ROUTE-03`)."""

ROLES = frozenset(k.name for k in kinds.KINDS.values())

NonEmpty = Annotated[str, Meta(min_length=1)]


class RequirementShape(Shape):
    id: NonEmpty
    text: NonEmpty
    source: NonEmpty
    roles: tuple[str, ...] = ()


class CatalogueShape(Shape):
    requirements: Annotated[tuple[RequirementShape, ...], Meta(min_length=1)]
    catalogue: str = ""
    version: int = 1


@dataclass(frozen=True)
class Requirement:
    id: str
    text: str
    source: str
    roles: tuple[str, ...]


@dataclass(frozen=True)
class Catalogue:
    """The requirements of one file, in the file's order."""

    path: Path
    name: str
    requirements: Mapping[str, Requirement]

    def __contains__(self, rid: object) -> bool:
        return rid in self.requirements

    def unknown(self, ids: Iterable[str]) -> list[str]:
        """The ids of `ids` the catalogue does not hold, in their order."""
        return [i for i in ids if i not in self.requirements]

    def check_ids(self, ids: Iterable[str], file: str | Path, place: str) -> None:
        """Refuse ids not in the catalogue: one ConfigError naming `file` and `place` (a key
        path, a step, a case)."""
        missing = self.unknown(ids)
        if missing:
            raise ConfigError(
                file, place,
                f"{', '.join(excerpt(m) for m in missing)} not in the requirements catalogue "
                f"{self.path} ({len(self.requirements)} requirements; ids like "
                f"{next(iter(self.requirements))})",
            )  # fmt: skip


def default_path() -> Path:
    """The shipped catalogue."""
    return data_dir("emulators") / "requirements" / "ktcs.yaml"


def load_catalogue(path: str | Path | None = None) -> Catalogue:
    """The catalogue at `path` (None: the shipped one), checked whole."""
    p = Path(path) if path is not None else default_path()
    doc = convert(load_mapping(p, "requirements catalogue"), CatalogueShape, p)
    out: dict[str, Requirement] = {}
    for i, r in enumerate(doc.requirements):
        place = f"requirements[{i}]"
        if not ID_PATTERN.match(r.id):
            raise located(p, f"{place}.id", f"{excerpt(r.id)} is no id: upper-case words "
                          "joined by hyphens, e.g. IXL-ROUTE-03")  # fmt: skip
        if r.id in out:
            raise located(p, f"{place}.id", f"{r.id} given twice")
        for j, role in enumerate(r.roles):
            if role not in ROLES:
                raise located(p, f"{place}.roles[{j}]", f"{excerpt(role)} is no device kind "
                              f"({', '.join(sorted(ROLES))})")  # fmt: skip
        out[r.id] = Requirement(r.id, r.text, r.source, r.roles)
    return Catalogue(p, doc.catalogue or p.stem, out)


_SHIPPED: list[Catalogue] = []


def shipped_catalogue() -> Catalogue:
    """The shipped catalogue, read once per process (every procedure file checks against it)."""
    if not _SHIPPED:
        _SHIPPED.append(load_catalogue())
    return _SHIPPED[0]
