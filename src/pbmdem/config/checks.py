"""Checks of a configuration that a JSON schema cannot express.

Number fractions that sum to 1, ascending diameters, particles that fit the bowl, a bed that
covers the impeller, names that exist, one seed per ensemble member. Every message names the key,
the offending value and what is allowed; all problems are reported at once.
"""

from __future__ import annotations

import math

from .design import problems as design_problems
from .errors import ConfigError
from .points import feed_case_names, feed_case_parents

FRACTION_TOLERANCE = 1e-6


def check(cfg) -> None:
    """Raise ConfigError listing every problem of the typed configuration `cfg` (a Config)."""
    problems: list[str] = []
    bowl, imp, bed = cfg.granulator.bowl, cfg.granulator.impeller, cfg.granulator.bed
    radius = bowl.radius
    if imp.blade_length >= radius:
        problems.append(
            f"granulator.impeller.blade_length = {imp.blade_length}: must be smaller than the bowl radius {radius}"
        )
    if imp.hub_diameter / 2 >= imp.blade_length:
        problems.append(
            f"granulator.impeller.hub_diameter = {imp.hub_diameter}: must be smaller than "
            f"twice the blade length {2 * imp.blade_length}"
        )
    top = imp.top
    if top >= bowl.height:
        problems.append(
            f"granulator.impeller: the blades reach z = {top:.6g} m (clearance, blade height and "
            f"pitch), which must be below the bowl height {bowl.height}"
        )
    if bed.height <= top:
        problems.append(
            f"dem.bed_height = {bed.height}: the bed must cover the impeller, i.e. exceed the "
            f"blade top at {top:.6g} m (clearance + blade height, with the pitch)"
        )
    if bed.height >= bowl.height:
        problems.append(f"dem.bed_height = {bed.height}: must be below the bowl height {bowl.height}")
    for name, dist in cfg.size_distributions.items():
        d, w = dist.diameters, dist.number_fractions
        key = f"size_distributions.{name}"
        if len(d) != len(w):
            problems.append(f"{key}: {len(d)} diameters but {len(w)} number_fractions; one fraction per class")
            continue
        if any(b <= a for a, b in zip(d, d[1:])):
            problems.append(f"{key}.diameters = {list(d)}: must be strictly ascending (class k is the k-th size)")
        total = math.fsum(w)
        if abs(total - 1.0) > FRACTION_TOLERANCE:
            problems.append(
                f"{key}.number_fractions = {list(w)}: sum to {total:.6g}, must sum to 1 (within {FRACTION_TOLERANCE})"
            )
        d_max = max(d)
        if d_max >= cfg.granulator.particle_diameter_limit:
            problems.append(
                f"{key}.diameters: largest {d_max} m does not fit the bowl: it must be below "
                f"{cfg.granulator.particle_diameter_limit:.4g} m (a third of the {bowl.height - top:.4g} m "
                f"above the impeller, and half the bowl radius, {radius / 2:.4g} m)"
            )
    grid = cfg.grid
    if grid.count() > grid.max_points:
        problems.append(
            f"grid: {len(grid.impeller_rpm)} impeller_rpm x {len(grid.size_distributions)} size_distributions "
            f"+ {len(grid.extra_points)} extra_points + {len(grid.design_points)} design_points = {grid.count()} "
            f"operating points, more than "
            f"grid.max_points = {grid.max_points} (raise it if the grid is meant to be this large)"
        )
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
    names = [("grid.size_distributions", name) for name in grid.size_distributions]
    for key in ("extra_points", "design_points"):
        names += [(f"grid.{key}[{k}].distribution", p.distribution) for k, p in enumerate(getattr(grid, key))]
    for where, name in [*names, ("validation.distribution", cfg.validation.distribution)]:
        if name not in cfg.size_distributions:
            problems.append(f"{where}: {name!r} is not defined; defined names: {sorted(cfg.size_distributions)}")
    feed, feeds = cfg.validation.feed_check.feed, grid.size_distributions
    if feed is not None and all(name in cfg.size_distributions for name in feeds):  # (else reported above)
        cases = feed_case_parents(feed_case_names({name: cfg.size_distributions[name] for name in feeds}))
        if feed not in cases:
            problems.append(
                f"validation.feed_check.feed = {feed!r}: not a case of the feed study with a grid feed on either "
                f"side (allowed: {list(cases) or 'none: the grid has fewer than two size distributions'}, or null "
                "for no check)"
            )
    sweep = cfg.validation.sweep
    if not sweep.stop > sweep.start:
        problems.append(f"validation.sweep: stop = {sweep.stop:g} must be greater than start = {sweep.start:g}")
    problems += cfg.surrogate.problems()
    problems += design_problems(cfg)
    if problems:
        raise ConfigError("invalid configuration:\n  " + "\n  ".join(problems))
