"""The ERA braking-curve frames (EFS project) as acceptance data for the ATP's curves.

Owns reading a frame's XML — train (Gamma brake models or Lambda brake percentage with the
conversion model of Subset-026 §3.13.3), track (gradients), national and fixed values, and the
targets and speeds each expectation asks about — and computing what our curves give for them.
Nothing is re-typed: every number comes from the frame, except the Subset-026 constants of the
conversion model itself, which are part of the standard, not of a train.

Run `python -m ktcs_bench.train.golden [GOLDEN_DIR]` to print the worst error per frame.
"""

from __future__ import annotations

import csv
import math
import os
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from ktcs_bench.errors import ConfigError
from ktcs_bench.train.curves import (
    CurveTimes,
    FixedValues,
    Target,
    TargetKind,
    curve_distances,
)
from ktcs_bench.train.deceleration import (
    GradientProfile,
    RotatingMass,
    SafeDeceleration,
    StepFunction,
)
from ktcs_bench.train.units import kmh

GOLDEN_ENV = "KTCS_GOLDEN_DIR"
CURVES = ("A_Safe", "EBD", "EBI", "SBI2", "Warning", "Permitted", "Indication")
_FUNC_TO_CURVE = {
    "EBDDistanceFromTarget": "EBD",
    "EBIDistanceFromTarget": "EBI",
    "SBIDistanceFromTarget": "SBI2",
    "WarningDistanceFromTarget": "Warning",
    "PermittedDistanceFromTarget": "Permitted",
    "IndicationDistanceFromTarget": "Indication",
}
_NUM = r"(-?[0-9.]+|Default\.BaseTypes\.\w+\.Infinity)"

# Subset-026 §3.13.3.4 conversion model (λ → A_brake_emergency): band lower speeds in km/h and
# the cubic coefficients A0..A3 of each band; below V_lim = 16.85·λ^0.428 the deceleration is
# 0.0075·λ + 0.076.
_CM_BANDS = (0.0, 100.0, 120.0, 150.0, 180.0)
_CM_COEF = (
    (0.0663, 4.72e-3, 6.1e-5, -6.3e-7),
    (0.13, 5.14e-3, -4.54e-6, 2.73e-7),
    (0.0479, 5.81e-3, -6.76e-6, 5.58e-8),
    (0.048, 5.52e-3, -3.85e-6, 3e-8),
    (0.0559, 5.06e-3, 1.66e-6, 3.23e-9),
)
# Brake build-up time T_brake_basic = a + b·(L/100) + c·(L/100)², per brake position and length
# class (§3.13.3.4.3), with the length floor where the standard sets one.
_TBB_EB = {
    "PassengerTrainInP": ((2.30, 0.0, 0.17, 400.0), (2.30, 0.0, 0.17, 400.0)),
    "FreightTrainInP": ((2.30, 0.0, 0.17, 400.0), (-0.4, 1.6, 0.03, 0.0)),
    "FreightTrainInG": ((12.0, 0.0, 0.05, 0.0), (-0.4, 1.6, 0.03, 0.0)),
}
_TBB_SB = {
    "PassengerTrainInP": ((3.0, 1.5, 0.1, 0.0), (3.0, 1.5, 0.1, 0.0)),
    "FreightTrainInP": ((3.0, 2.77, 0.0, 0.0), (10.5, 0.32, 0.18, 0.0)),
    "FreightTrainInG": ((3.0, 2.77, 0.0, 400.0), (10.5, 0.32, 0.18, 0.0)),
}
_KTO_CT = {"PassengerTrainInP": 0.20, "FreightTrainInP": 0.20, "FreightTrainInG": 0.16}
_SPECIAL = (
    ("EddyCurrent", "EddyCurrentBrakeIsActive", "EddyCurrentBrakeInterface"),
    ("Magnetic", "MagneticShoeBrakeIsActive", "MagneticShoeBrakeInterface"),
    ("Regenerative", "RegenerativeBrakeIsActive", "RegenerativeBrakeInterface"),
)


def golden_dir() -> Path:
    """Where the golden data is: $KTCS_GOLDEN_DIR, else <repo>/../shared/golden."""
    env = os.environ.get(GOLDEN_ENV)
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2].parent / "shared" / "golden"


def _num(text: str) -> float:
    return math.inf if "Infinity" in text else float(text)


@dataclass
class FrameData:
    """The assignments of one frame's set-up actions, and its expectations."""

    name: str
    values: dict[str, str] = field(default_factory=dict)
    gradients: list[tuple[float, float]] = field(default_factory=list)
    # (curve, target location, target speed km/h, speed km/h, A_safe distance or nan)
    queries: list[tuple[str, float, float, float, float]] = field(default_factory=list)

    def get(self, key: str, default: str | None = None) -> str:
        for k, v in self.values.items():
            if k.endswith(key):
                return v
        if default is None:
            raise ConfigError(self.name, key, "missing in frame")
        return default

    def number(self, key: str, default: float | None = None) -> float:
        raw = self.get(key, None if default is None else str(default))
        m = re.search(_NUM, raw)
        if not m:
            raise ConfigError(self.name, key, f"not a number: {raw!r}")
        return _num(m.group(1))

    def fields(self, key: str) -> dict[str, str]:
        return dict(re.findall(r"(\w+)\s*=>\s*([^,}\s]+)", self.get(key)))

    def table(self, prefix: str) -> list[dict[str, str]]:
        """ValN structures under prefix (e.g. '...ModelSet.Regenerative'), in N order."""
        rows: list[tuple[int, dict[str, str]]] = []
        for k, v in self.values.items():
            m = re.fullmatch(re.escape(prefix) + r"\.Val(\d+)", k)
            if m:
                rows.append((int(m.group(1)), dict(re.findall(r"(\w+)\s*=>\s*([^,}\s]+)", v))))
        return [r for _, r in sorted(rows)]


def parse_frame(path: Path) -> FrameData:
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise ConfigError(path, "", f"cannot read frame: {exc}") from None
    data = FrameData(root.get("Name") or path.stem)
    for act in root.iter("Action"):
        text = re.sub(r"\s+", " ", act.text or "").strip()
        if text.startswith("INSERT") and "GradientStruct" in text:
            m = re.search(r"Location => " + _NUM + r".*Gradient => " + _NUM, text)
            if m:
                data.gradients.append((_num(m.group(1)), _num(m.group(2))))
            continue
        if "<-" in text:
            key, value = (s.strip() for s in text.split("<-", 1))
            data.values[key] = value
    tgt = r"Target \{ Speed => " + _NUM + r", Location => " + _NUM
    for exp in root.iter("Expectation"):
        text = re.sub(r"\s+", " ", exp.text or "").strip()
        m = re.search(r"ERA_BrakingCurvesVerification\.(\w+DistanceFromTarget)", text)
        if m and m.group(1) in _FUNC_TO_CURVE:
            t = re.search(tgt, text)
            sp = re.search(r"aSpeed => " + _NUM, text)
            if t and sp:
                data.queries.append(
                    (_FUNC_TO_CURVE[m.group(1)], _num(t[2]), _num(t[1]), _num(sp[1]), math.nan)
                )
            continue
        if "A_safe" in text:
            t = re.search(tgt + r".*d => " + _NUM + r"\), V => " + _NUM, text)
            if t:
                data.queries.append(("A_Safe", _num(t[2]), _num(t[1]), _num(t[4]), _num(t[3])))
    return data


@dataclass(frozen=True)
class FrameModel:
    """What the ATP needs from a frame: safe deceleration, curve times and fixed values."""

    decel: SafeDeceleration
    times: CurveTimes
    train_length: float
    v_mrsp: float
    """MRSP over the frame's track: min(train maximum speed, signalling-related restriction)."""


def _enum_tail(raw: str) -> str:
    return raw.rsplit(".", 1)[-1]


def _conversion_decel(lam: float) -> StepFunction:
    v_lim = 16.85 * lam**0.428
    a0 = 0.0075 * lam + 0.076
    steps, values = [0.0], [a0]

    def band(n: int) -> float:
        c = _CM_COEF[n]
        return c[0] + c[1] * lam + c[2] * lam**2 + c[3] * lam**3

    for n, lower in enumerate(_CM_BANDS):
        upper = _CM_BANDS[n + 1] if n + 1 < len(_CM_BANDS) else math.inf
        if upper <= v_lim:
            continue
        start = max(lower, v_lim)
        steps.append(kmh(start))
        values.append(band(n))
    return StepFunction(tuple(steps), tuple(values))


def _t_basic(
    table: Mapping[str, tuple[tuple[float, float, float, float], ...]], position: str, length: float
) -> float:
    a, b, c, floor = table[position][0 if length <= 900.0 else 1]
    ll = max(length, floor) / 100.0
    return a + b * ll + c * ll * ll


def _step_from_rows(rows: list[dict[str, str]], key: str, value: str, scale: float) -> StepFunction:
    pairs = [(_num(r[key]) * scale, _num(r[value])) for r in rows if math.isfinite(_num(r[key]))]
    pairs.sort()
    return StepFunction(tuple(p[0] for p in pairs), tuple(p[1] for p in pairs))


def build_model(f: FrameData) -> FrameModel:
    """Train and track of a frame → safe deceleration and curve times (Subset-026 §3.13)."""
    tv = "Kernel.TrainData.TrainData.Value"
    nv = "Kernel.NationalValues.ApplicableNationalValues.Value"
    length = f.number(f"{tv}.TrainLength")
    position = _enum_tail(f.get(f"{tv}.BrakePosition"))
    fixed = FixedValues(
        dv_ebi_min=kmh(f.number("dV_ebi_min")),
        dv_ebi_max=kmh(f.number("dV_ebi_max")),
        v_ebi_min=kmh(f.number("V_ebi_min")),
        v_ebi_max=kmh(f.number("V_ebi_max")),
        dv_sbi_min=kmh(f.number("dV_sbi_min")),
        dv_sbi_max=kmh(f.number("dV_sbi_max")),
        v_sbi_min=kmh(f.number("V_sbi_min")),
        v_sbi_max=kmh(f.number("V_sbi_max")),
        dv_warning_min=kmh(f.number("dV_warning_min")),
        dv_warning_max=kmh(f.number("dV_warning_max")),
        v_warning_min=kmh(f.number("V_warning_min")),
        v_warning_max=kmh(f.number("V_warning_max")),
        t_warning=f.number("TargetSpeedMonitoring.T_warning"),
        t_driver=f.number("TargetSpeedMonitoring.T_driver"),
    )
    m_nom_raw = f.get(f"{tv}.M_rotating_nom", "NA")
    rotating = RotatingMass(
        nominal=None if "NA" in m_nom_raw else _num(m_nom_raw),
        minimum=f.number("Gradient.M_rotating_min"),
        maximum=f.number("Gradient.M_rotating_max"),
    )
    lam_raw = f.get(f"{tv}.BrakePercentage", "NA")
    sb_cmd = _enum_tail(f.get(f"{tv}.SBCommandIsImplemented", "False")) == "True"
    if "NA" not in lam_raw:  # Lambda train: the conversion model
        lam = _num(lam_raw)
        a_eb = _conversion_decel(lam)
        kr = _step_from_rows(
            f.table(f"{nv}.IntegratedCorrectionFactorKrInt"), "LengthStep", "Value", 1.0
        )(length)
        if position == "PassengerTrainInP":
            a_max = max(a_eb.values)
            p12 = f.number(f"{nv}.IntegratedCorrectionFactorKvInt_PassengerTrain.A_NVP12")
            p23 = f.number(f"{nv}.IntegratedCorrectionFactorKvInt_PassengerTrain.A_NVP23")
            rows = f.table(f"{nv}.IntegratedCorrectionFactorKvInt_PassengerTrain")
            ka = _step_from_rows(rows, "SpeedStep", "ValueA", 1.0 / 3.6)
            kb = _step_from_rows(rows, "SpeedStep", "ValueB", 1.0 / 3.6)
            w = min(max((a_max - p12) / (p23 - p12), 0.0), 1.0)
            kv = StepFunction(
                ka.steps,
                tuple(
                    a + w * (b - a)
                    for a, b in zip(ka.values, (kb(s) for s in ka.steps), strict=True)
                ),
            )
        else:
            kv = _step_from_rows(
                f.table(f"{nv}.IntegratedCorrectionFactorKvInt_FreightTrain"),
                "SpeedStep",
                "Value",
                1.0 / 3.6,
            )
        kv = StepFunction(kv.steps, tuple(k * kr for k in kv.values))
        brake = a_eb.scaled(kv)
        kt = f.number(f"{nv}.IntegratedCorrectionFactorForBrakeBuildUpTime", 1.0)
        t_be = kt * _t_basic(_TBB_EB, position, length)
        t_bs = kt * _t_basic(_TBB_SB, position, length)
    else:  # Gamma train: brake models of the active special-brake combination
        eb_combo = _combination(f, "EB")
        sb_combo = _combination(f, "SB")
        model = f.table(f"{tv}.EBModels.ModelSet.{eb_combo}")
        a_eb = _step_from_rows(model, "SpeedStep", "Acceleration", 1.0 / 3.6)
        cl = _enum_tail(f.get(f"{nv}.ConfLevelForEmergBrakeSafeDecelerationOnDryRails"))
        kdry = _cf(f, f"{tv}.EBModels.Kdry_rstValuesSet.{eb_combo}.{_cl_key(cl)}", a_eb)
        kwet = _cf(f, f"{tv}.EBModels.Kwet_rstValuesSet.{eb_combo}", a_eb)
        avadh = f.number(f"{nv}.WeightingFactorForAvailableWheelRailAdhesion", 0.0)
        factor = StepFunction(
            a_eb.steps,
            tuple(d * (w + avadh * (1.0 - w)) for d, w in zip(kdry, kwet, strict=True)),
        )
        brake = a_eb.scaled(factor)
        t_be = f.number(f"{tv}.T_brake_emergency.{eb_combo}")
        t_bs = f.number(f"{tv}.T_brake_service.{sb_combo}")
    times = CurveTimes(t_be=t_be, t_bs=t_bs, service_brake_command=sb_cmd, fixed=fixed)
    grads = sorted(f.gradients)
    profile = GradientProfile(tuple(g[0] for g in grads), tuple(g[1] for g in grads))
    decel = SafeDeceleration(brake, profile.compensated(length), rotating)
    v_mrsp = kmh(f.number(f"{tv}.MaximumSpeed"))
    ssr = f.fields("Kernel.MA.SignallingRelatedSpeedRestriction")
    if "Value" in ssr:
        v_mrsp = min(v_mrsp, kmh(_num(ssr["Value"])))
    return FrameModel(decel, times, length, v_mrsp)


def _cl_key(conf_level: str) -> str:
    # M_NVEBCL enum "Confidence_level___99_9999999" → Kdry set key "Cl__99_9999999"
    return "Cl__" + conf_level.split("___", 1)[-1]


def _cf(f: FrameData, key: str, model: StepFunction) -> list[float]:
    """Correction factors CF0..CFn, one per speed step of the brake model."""
    vals = f.fields(key)
    cfs = [_num(vals[f"CF{i}"]) for i in range(7) if f"CF{i}" in vals]
    if not cfs:
        raise ConfigError(f.name, key, "no correction factors")
    return [cfs[min(i, len(cfs) - 1)] for i in range(len(model.steps))]


def _combination(f: FrameData, brake: str) -> str:
    """Name of the active special-brake combination for the EB or SB models."""
    tv = "Kernel.TrainData.TrainData.Value"
    allowed = _enum_tail(f.get("ContributionOfSpecialBrakeIsAllowed", "True")) == "True"
    parts = []
    for name, status, interface in _SPECIAL:
        active = _enum_tail(f.get(f"TIU.SpecialBrakeStatus.{status}", "False")) == "True"
        iface = _enum_tail(f.get(f"{tv}.{interface}", "None"))
        if allowed and active and iface in (brake, "Both"):
            parts.append(name)
    return "_".join(parts) if parts else "NoSpecialBrake"


@dataclass(frozen=True)
class Comparison:
    frame: str
    curve: str
    speed_kmh: float
    expected: float
    computed: float

    @property
    def error(self) -> float:
        return abs(self.computed - self.expected)


def compute_frame(f: FrameData) -> dict[tuple[str, float], float]:
    """Our value for every (curve, speed km/h) the frame asks about."""
    model = build_model(f)
    out: dict[tuple[str, float], float] = {}
    for curve, loc, tspeed, speed, d in f.queries:
        target = Target(loc, kmh(tspeed), TargetKind.SPEED)
        if curve == "A_Safe":
            out[(curve, speed)] = model.decel.at(kmh(speed), loc - d)
            continue
        cd = curve_distances(model.decel, target, model.times, kmh(speed), v_mrsp=model.v_mrsp)
        out[(curve, speed)] = {
            "EBD": cd.ebd,
            "EBI": cd.ebi,
            "SBI2": cd.sbi2,
            "Warning": cd.warning,
            "Permitted": cd.permitted,
            "Indication": cd.indication,
        }[curve]
    return out


def compare_all(root: Path | None = None) -> list[Comparison]:
    """Every row of expected.csv against our computation of its frame."""
    base = (root or golden_dir()) / "era-braking-curves"
    expected_path = base / "expected.csv"
    try:
        with expected_path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise ConfigError(expected_path, "", f"cannot read: {exc}") from None
    computed: dict[str, dict[tuple[str, float], float]] = {}
    result = []
    for row in rows:
        frame = row["frame"]
        if frame not in computed:
            computed[frame] = compute_frame(parse_frame(base / "frames" / f"{frame}.xml"))
        key = (row["curve"], float(row["speed_kmh"]))
        if key not in computed[frame]:
            raise ConfigError(expected_path, f"{frame}/{key}", "no matching expectation in frame")
        result.append(
            Comparison(frame, row["curve"], key[1], float(row["value"]), computed[frame][key])
        )
    return result


def worst_per_frame(comps: list[Comparison]) -> dict[str, tuple[float, float]]:
    """frame → (worst distance error m, worst A_safe error m/s²)."""
    out: dict[str, tuple[float, float]] = {}
    for c in comps:
        d, a = out.get(c.frame, (0.0, 0.0))
        if c.curve == "A_Safe":
            a = max(a, c.error)
        else:
            d = max(d, c.error)
        out[c.frame] = (d, a)
    return out


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    comps = compare_all(Path(args[0]) if args else None)
    worst = worst_per_frame(comps)
    print("| frame | rows | worst distance error (m) | worst A_safe error (m/s²) |")
    print("|---|---|---|---|")
    for frame, (d, a) in worst.items():
        n = sum(1 for c in comps if c.frame == frame)
        a_txt = f"{a:.4f}" if any(c.frame == frame and c.curve == "A_Safe" for c in comps) else "—"
        print(f"| {frame} | {n} | {d:.3f} | {a_txt} |")
    bad = [c for c in comps if c.error > (0.01 if c.curve == "A_Safe" else 0.5)]
    print(f"\n{len(comps)} rows, {len(bad)} outside tolerance (0.5 m; A_safe 0.01 m/s²)")
    for c in bad[:20]:
        print(
            f"  {c.frame} {c.curve} {c.speed_kmh} km/h: expected {c.expected}, got {c.computed:.3f}"
        )
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main())
