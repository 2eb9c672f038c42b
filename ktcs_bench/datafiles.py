"""Where the shipped data folders are, in a checkout and in an installed wheel.

`protocols/`, `code_charts/` and `emulators/` sit at the repository's top level; the wheel carries
them as `ktcs_bench/_data/<name>` (hatchling force-include). Every loader asks here.
"""

from __future__ import annotations

from pathlib import Path

from ktcs_bench.errors import ConfigError

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """The shipped data folder `name` ("protocols", "code_charts" or "emulators")."""
    for candidate in (_PACKAGE / "_data" / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise ConfigError(name, "", "shipped data folder not found (broken installation?)")


def load_yaml(path: str | Path) -> object:
    """Parse one YAML file; a syntax error becomes a ConfigError naming file, line and column."""
    import yaml

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(p, "", f"cannot read: {exc.strerror or exc}") from None
    try:
        return yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        place = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ConfigError(p, place, f"invalid YAML: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(p, "", f"invalid YAML: {exc}") from None
