"""The ATP's curves against the ERA braking-curve frames (shared/golden/era-braking-curves)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ktcs_bench.train import golden

ROOT = golden.golden_dir()


def _require_golden() -> None:
    """The frames are the acceptance data of the curves: missing data fails, it never skips."""
    expected = ROOT / "era-braking-curves" / "expected.csv"
    if not expected.is_file():
        pytest.fail(
            f"golden data missing: {expected} not found. The ERA braking-curve frames are the "
            f"acceptance check of the ATP curves; put them at <repo>/../shared/golden or point "
            f"${golden.GOLDEN_ENV} at the folder holding era-braking-curves/.",
            pytrace=False,
        )


@pytest.fixture(scope="module")
def comparisons() -> list[golden.Comparison]:
    _require_golden()
    return golden.compare_all(ROOT)


def test_every_expected_row_is_computed(comparisons: list[golden.Comparison]) -> None:
    lines = (ROOT / "era-braking-curves" / "expected.csv").read_text().strip().splitlines()
    assert len(comparisons) == len(lines) - 1
    assert {c.frame for c in comparisons} == {
        p.stem for p in (ROOT / "era-braking-curves" / "frames").glob("*.xml")
    }


def test_distances_within_half_a_metre(comparisons: list[golden.Comparison]) -> None:
    bad = [c for c in comparisons if c.curve != "A_Safe" and c.error > 0.5]
    assert not bad, [(c.frame, c.curve, c.speed_kmh, c.expected, c.computed) for c in bad[:10]]


def test_a_safe_within_a_hundredth(comparisons: list[golden.Comparison]) -> None:
    rows = [c for c in comparisons if c.curve == "A_Safe"]
    assert rows
    bad = [c for c in rows if c.error > 0.01]
    assert not bad, [(c.frame, c.speed_kmh, c.expected, c.computed) for c in bad]


def test_frame_values_are_read_not_retyped() -> None:
    _require_golden()
    frame = golden.parse_frame(ROOT / "era-braking-curves" / "frames" / "Lambda FrInG 100%.xml")
    model = golden.build_model(frame)
    # the frame itself states these intermediate results (T_be() == 14.45, T_bs() == 22.39)
    assert model.times.t_be == pytest.approx(14.45, abs=0.005)
    assert model.times.t_bs == pytest.approx(22.39, abs=0.005)
    assert model.train_length == 700.0


def test_golden_dir_follows_the_environment(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv(golden.GOLDEN_ENV, str(tmp_path))
    assert golden.golden_dir() == tmp_path
