"""What the report states in words: the targets of the validation, met or not met with the
measured values, and where the surrogate left its training domain, interval by interval
(docs/validation.md, "Report": Targets, Out-of-domain statement).
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

import pandas as pd

from . import words
from .display import MM, missing, number, percent


@dataclass(frozen=True)
class Target:
    column: str
    relation: str  # "<=", ">=" or "=="
    threshold: float
    goal: str
    unit: str = ""

    def met(self, value) -> bool:
        if missing(value):
            return False
        return {"<=": operator.le, ">=": operator.ge, "==": operator.eq}[self.relation](float(value), self.threshold)

    def shown(self, value) -> str:
        """A measured value (or the threshold) in the target's display unit."""
        if self.unit == "%":
            return f"{percent(value)} %"
        if self.unit == "x":
            return f"{number(value, '.0f')}x"
        return number(value, ".0f")

    @property
    def criterion(self) -> str:
        relation = "=" if self.relation == "==" else self.relation
        return f"{self.column} {relation} {self.shown(self.threshold)}"


TARGETS = (
    Target("ann_d50_outside_band_max", "<=", 0.01, "PBM-ANN's d50(t) within 1 % of the PBM-DEM replicate band", "%"),
    Target("ann_out_of_domain_intervals", "==", 0, "PBM-ANN never outside the surrogate's training domain"),
    Target("cpu_time_ratio_dem_over_ann", ">=", 3000, "PBM-ANN at least 3000x faster than PBM-DEM (CPU time)", "x"),
)


def targets(table: pd.DataFrame) -> pd.DataFrame:
    """One row per target and validation speed: target, criterion, speed (rpm), measured, met."""
    rows = []
    for target in TARGETS:
        for r in table.to_dict("records"):
            value = r.get(target.column, float("nan"))
            measured = target.shown(value)
            if target.column == "ann_out_of_domain_intervals" and "ann_intervals" in r:
                measured = f"{number(value, '.0f')} of {number(r['ann_intervals'], '.0f')} intervals"
            met = target.met(value)
            rows.append(
                {
                    "target": target.goal,
                    "criterion": target.criterion,
                    "speed (rpm)": f"{r['rpm']:g}",
                    "measured": measured,
                    "met": "met" if met else ("not met (not measured)" if measured.startswith("n/a") else "not met"),
                }
            )
    return pd.DataFrame(rows, columns=["target", "criterion", "speed (rpm)", "measured", "met"])


def target_sentences(table: pd.DataFrame) -> list[str]:
    """One sentence per target: met at every speed, or not met, with the measured values."""
    rows = targets(table)
    out = []
    for target in TARGETS:
        mine = rows[rows.target == target.goal]
        out.append(
            words.paragraph(
                "target",
                goal=target.goal,
                criterion=target.criterion,
                measured=list(zip(mine.measured, mine["speed (rpm)"])),
                not_met=list(mine.loc[mine.met != "met", "speed (rpm)"]),
            )
        )
    return out


def _classes(diameters) -> str:
    """The sample's class diameters (an array of the contract's reader) in mm; n/a without them."""
    return "n/a" if diameters is None else ", ".join(f"{MM * d:.2f}" for d in diameters)


def _messages(value) -> str:
    return "" if missing(value) else str(value)


def out_of_domain(speed) -> pd.DataFrame:
    """Interval by interval, every PBM-ANN interval, every ensemble member and the constant kernel's
    calibration: where the surrogate was outside its training domain (no "what lay outside" when nothing was)."""
    ann = speed.ann.intervals
    rows = []
    recorded = ann is not None and "out_of_domain_count" in ann.columns
    for r in ann.to_dict("records") if ann is not None else []:
        count = r.get("out_of_domain_count", float("nan"))
        known = recorded and not missing(count)
        rows.append(
            {
                "model": "PBM-ANN (ensemble mean)",
                "interval": str(int(r["interval"])),
                "start (s)": number(r["t_start"], ".4g"),
                "end (s)": number(r["t_end"], ".4g"),
                "sample classes (mm)": _classes(r.get("class_diameters")),
                "sample particles (count)": number(r.get("sample_particles", float("nan")), ".0f"),
                "outside the training domain": ("yes" if count > 0 else "no") if known else "not recorded",
                "warnings (count)": number(count, ".0f") if known else "not recorded",
                "what lay outside": _messages(r.get("out_of_domain")),
            }
        )
    n_intervals = len(ann) if ann is not None else 0
    members = speed.members
    if members is not None and len(members) and "out_of_domain_intervals" in members.columns:
        for member, g in members.groupby("member"):
            k = int(g.out_of_domain_intervals.max())
            rows.append(
                {
                    "model": f"PBM-ANN member {int(member)}",
                    "interval": f"all {n_intervals}",
                    "start (s)": number(g.time.min(), ".4g"),
                    "end (s)": number(g.time.max(), ".4g"),
                    "sample classes (mm)": "as above",
                    "sample particles (count)": "as above",
                    "outside the training domain": f"{k} of {n_intervals} intervals",
                    "warnings (count)": "not recorded per member",
                    "what lay outside": "",
                }
            )
    timing = speed.constant.timing
    count = timing.get("out_of_domain_count", float("nan"))
    known = not missing(count)
    first = ann.iloc[0] if ann is not None and len(ann) else {}
    rows.append(
        {
            "model": "PBM-constant calibration",
            "interval": "initial sample",
            "start (s)": "0",
            "end (s)": "0",
            "sample classes (mm)": _classes(first.get("class_diameters")),
            "sample particles (count)": number(first.get("sample_particles", float("nan")), ".0f"),
            "outside the training domain": ("yes" if count > 0 else "no") if known else "not recorded",
            "warnings (count)": number(count, ".0f") if known else "not recorded",
            "what lay outside": _messages(timing.get("out_of_domain")),
        }
    )
    frame = pd.DataFrame(rows)
    if not frame["what lay outside"].astype(bool).any():  # nothing lay outside: no empty column
        frame = frame.drop(columns="what lay outside")
    return frame


def out_of_domain_sentence(rpm: str, table: pd.DataFrame) -> str:
    """The statement of one speed in words, from `out_of_domain(speed)`."""
    ann = table[table.model == "PBM-ANN (ensemble mean)"]
    outside = ann[ann["outside the training domain"] == "yes"]
    members = table[table.model.str.startswith("PBM-ANN member")]
    cal = table[table.model == "PBM-constant calibration"]
    return words.paragraph(
        "out_of_domain",
        rpm=rpm,
        intervals=len(ann),
        unknown=int((ann["outside the training domain"] == "not recorded").sum()),
        outside=[
            {
                "interval": r["interval"],
                "start": r["start (s)"],
                "end": r["end (s)"],
                "warnings": r["warnings (count)"],
                "what": r.get("what lay outside", ""),
            }
            for _, r in outside.iterrows()
        ],
        members=[(r["model"].split()[-1], r["outside the training domain"]) for _, r in members.iterrows()],
        calibration=cal["outside the training domain"].iloc[0] if len(cal) else None,
        calibration_warnings=cal["warnings (count)"].iloc[0] if len(cal) else None,
    )
