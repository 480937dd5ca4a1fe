"""The DEM stage: LIGGGHTS runs of the granulator and their collision and encounter tables.

| module | concept |
| --- | --- |
| `geometry` | bowl and impeller STL meshes |
| `plan` | the plan of one run: every decision (particles, time step, phases, snapshots, seeds, deck values) |
| `deck` | the LIGGGHTS deck: a plan formatted as text |
| `engine` | running LIGGGHTS, judging a run against its plan, recording crashes |
| `signals` | the engine's process: SIGINT/SIGTERM passed on, killed with its children, waited for |
| `progress` | progress of a running job from its thermo output |
| `run` | one run end to end in a staging folder |
| `dumps` | reading LIGGGHTS dump files |
| `encounters` | impacts of granules that were apart, and their impact velocities |
| `collisions` | the collision and encounter tables of one run |
| `grid_tables` | the grid's tables: replicate means and standard errors, the run table |
| `speed_response` | encounter rate against impeller speed, flow development |
| `viewer` | pyvista view / screenshot of a run, and the `.pvd` index of its VTK snapshots |
"""

from .plan import DemPlan, plan_point
from .run import run_point

__all__ = ["DemPlan", "plan_point", "run_point"]
