"""The sensitivity finding: which factor the final d50 depends on most over the stated ranges (the
Sobol' indices of results/design/sensitivity.csv, pbmdem.design.sensitivity), and whether the
surrogate's members agree on that ranking, in words."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pbmdem.design.sensitivity import label

from . import words

#: a total index below this is called negligible (a factor that causes under 5 % of the variance)
NEGLIGIBLE = 0.05


def ranking(rows: pd.DataFrame) -> list[str]:
    """The factors of `rows` (one output, one member) by their total index ST, largest first."""
    return list(rows.sort_values("ST", ascending=False, kind="stable").parameter)


def _indices(row) -> dict:
    return {k: row[k] for k in ("ST", "ST_conf", "S1", "S1_conf")}


def _members(d50: pd.DataFrame, order: list[str]) -> dict | None:
    """How the surrogate's members rank the factors (None: no members)."""
    members = d50[d50.member.astype(str) != "mean"]
    names = list(dict.fromkeys(members.member.astype(str)))
    if not names:
        return None
    defined = [m for m in names if np.isfinite(members[members.member.astype(str) == m].ST).all()]
    if not defined:
        return {"count": len(names), "defined": 0}
    firsts = {m: ranking(members[members.member.astype(str) == m])[0] for m in defined}
    top = members[members.parameter == order[0]].ST.to_numpy(float)
    return {
        "count": len(names),
        "defined": len(defined),
        "same_top": sum(first == order[0] for first in firsts.values()),
        "same_order": sum(ranking(members[members.member.astype(str) == m]) == order for m in defined),
        "top_min": np.nanmin(top),
        "top_max": np.nanmax(top),
        "others": sorted({label(f) for f in firsts.values() if f != order[0]}),
    }


def sensitivity_words(table: pd.DataFrame, confidence: float, info: dict | None = None) -> str:
    """The finding in words from the indices table (`pbmdem.design.sensitivity.COLUMNS`) and, with
    `info` (the rule's sensitivity.json), the samples outside the surrogate's training domain."""
    d50 = table[table.output == "d50"]
    mean = d50[d50.member.astype(str) == "mean"]
    if mean.empty or not np.isfinite(mean.ST).all():
        return words.paragraph("sensitivity", defined=False)
    order = ranking(mean)
    rows = mean.set_index("parameter")
    first, second = rows.loc[order[0]], (rows.loc[order[1]] if len(order) > 1 else None)
    return words.paragraph(
        "sensitivity",
        defined=True,
        factors=[label(p) for p in order],
        first=_indices(first),
        second=_indices(second) if second is not None else None,
        apart=second is None or not first.ST - first.ST_conf <= second.ST + second.ST_conf,
        confidence=confidence,
        small=[label(p) for p in order if rows.loc[p, "ST"] < NEGLIGIBLE],
        interactions=float(mean.ST.sum() - mean.S1.sum()),
        members=_members(d50, order),
        outside=info.get("out_of_domain_samples", {}).get("mean", 0) if info else None,
        samples=info.get("samples") if info else None,
    )
