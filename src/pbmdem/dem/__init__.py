"""The DEM stage: LIGGGHTS runs of the granulator and their collision and encounter tables.

Its modules, one concept each: docs/architecture.md ("Packages and modules").
"""

from .plan import DemPlan, plan_point
from .run import run_point

__all__ = ["DemPlan", "plan_point", "run_point"]
