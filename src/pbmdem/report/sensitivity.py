"""The sensitivity finding: which factor the final d50 depends on most over the stated ranges (the
Sobol' indices of results/design/sensitivity.csv, pbmdem.design.sensitivity), and whether the
surrogate's members agree on that ranking, in words."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.design.sensitivity import label

#: a total index below this is called negligible (a factor that causes under 5 % of the variance)
NEGLIGIBLE = 0.05


def ranking(rows: pd.DataFrame) -> list[str]:
    """The factors of `rows` (one output, one member) by their total index ST, largest first."""
    return list(rows.sort_values("ST", ascending=False, kind="stable").parameter)


def _index(row) -> str:
    return f"ST = {row.ST:.2f} ± {row.ST_conf:.2f}, S1 = {row.S1:.2f} ± {row.S1_conf:.2f}"


def _members_words(d50: pd.DataFrame, order: list[str]) -> str:
    members = d50[d50.member.astype(str) != "mean"]
    names = list(dict.fromkeys(members.member.astype(str)))
    if not names:
        return ""
    defined = [m for m in names if np.isfinite(members[members.member.astype(str) == m].ST).all()]
    if not defined:
        return "The members' indices are undefined (a batch failed or d50 did not vary). "
    firsts = {m: ranking(members[members.member.astype(str) == m])[0] for m in defined}
    same_top = sum(first == order[0] for first in firsts.values())
    same_order = sum(ranking(members[members.member.astype(str) == m]) == order for m in defined)
    top = members[members.parameter == order[0]].ST.to_numpy(float)
    words = (
        f"Computed with each of the surrogate's {len(names)} members instead of its mean, {label(order[0])} comes "
        f"first for {same_top} of {len(defined)} (ST from {np.nanmin(top):.2f} to {np.nanmax(top):.2f})"
    )
    others = sorted({label(f) for f in firsts.values() if f != order[0]})
    if others:
        words += f"; the others put {', '.join(others)} first"
    words += f", and {same_order} of {len(defined)} rank all {len(order)} factors as the mean does"
    return (
        words
        + (": the surrogate's uncertainty does not change the answer. " if same_top == len(defined) else ". ")
        + ("" if len(defined) == len(names) else f"{len(names) - len(defined)} member(s) had undefined indices. ")
    )


def _domain_words(info: dict | None) -> str:
    if not info:
        return ""
    outside = info.get("out_of_domain_samples", {}).get("mean", 0)
    if not outside:
        return "The surrogate stayed inside its training domain on every sample of the mean. "
    return (
        f"On {outside} of the mean's {info['samples']} samples ({100 * outside / info['samples']:.0f} %) the surrogate "
        "left its training domain (granules or beds unlike any the DEM grid held): those batches are "
        "extrapolations, kept in the indices. "
    )


def sensitivity_words(table: pd.DataFrame, confidence: float, info: dict | None = None) -> str:
    """The finding in words from the indices table (`pbmdem.design.sensitivity.COLUMNS`) and, with
    `info` (the rule's sensitivity.json), the samples outside the surrogate's training domain."""
    d50 = table[table.output == "d50"]
    mean = d50[d50.member.astype(str) == "mean"]
    head = "**Global sensitivity.** "
    if mean.empty or not np.isfinite(mean.ST).all():
        return head + "The Sobol' indices of the final d50 are undefined (a batch failed or d50 did not vary). "
    order = ranking(mean)
    rows = mean.set_index("parameter")
    first, second = rows.loc[order[0]], (rows.loc[order[1]] if len(order) > 1 else None)
    words = (
        f"Over the stated ranges of its {len(order)} factors (the figure's caption), the final d50 depends most "
        f"on the {label(order[0])} ({_index(first)}; {100 * confidence:g} % intervals)"
    )
    if second is not None:
        words += f", then on the {label(order[1])} ({_index(second)})"
        if first.ST - first.ST_conf <= second.ST + second.ST_conf:
            words += "; within their intervals these two are not told apart"
    words += ". "
    small = [label(p) for p in order if rows.loc[p, "ST"] < NEGLIGIBLE]
    if small:
        names = small[0] if len(small) == 1 else ", ".join(small[:-1]) + " and " + small[-1]
        words += f"The {names} cause{'s' if len(small) == 1 else ''} less than 5 % of its variance. "
    interactions = float(mean.ST.sum() - mean.S1.sum())
    if interactions > 0.1:
        words += (
            f"The total indices exceed the first-order ones by {interactions:.2f} in sum: part of the variance "
            "comes from factors acting together. "
        )
    return head + words + _members_words(d50, order) + _domain_words(info)
