"""Settings of the DEM stage: what one LIGGGHTS run computes, how many replicates, how it runs."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .typed import Settings, setting


class Dem(Settings):
    """What one DEM run computes (the `dem:` section without the bed, which belongs to the
    granulator, without `replicates`, which decides which runs exist, and without the execution
    settings, which change how a run is executed but not its result)."""

    max_particles: int = setting(20000, "most particles of one DEM bed", ge=2, le=10000000)
    timestep_fraction: float = setting(
        ..., "time step as a fraction of the smallest particle's Rayleigh time", gt=0, le=0.3
    )
    settle_time: float = setting(..., "settling of the poured bed", "s", gt=0, le=100)
    spinup_time: float = setting(
        ..., "minimum spin-up; the spin-up lasts at least spinup_revolutions", "s", gt=0, le=100
    )
    spinup_revolutions: float = setting(0.0, "minimum spin-up in impeller revolutions", ge=0, le=1000)
    sampling_time: float = setting(
        ..., "minimum sampling window; it lasts at least sampling_revolutions", "s", gt=0, le=100
    )
    sampling_revolutions: float = setting(0.0, "minimum sampling window in impeller revolutions", ge=0, le=1000)
    history_time: float = setting(
        0.05, "position history recorded before the sampling window, part of the spin-up", "s", gt=0, le=100
    )
    encounter_gap_fraction: float = setting(
        0.25,
        "an encounter needs a surface gap above this fraction of the smaller diameter since the previous contact",
        gt=0,
        le=10,
    )
    position_every: int = setting(2, "contact snapshots between two position snapshots", ge=1, le=1000)
    collision_interval: Annotated[int, Field(ge=1, le=100000)] | Literal["auto"] = setting(
        "auto", "steps between contact snapshots, or auto (half the Hertz contact time)"
    )
    vtk_interval: float = setting(0.02, "time between VTK snapshots", "s", gt=0, le=100)
    keep_contact_dumps: bool = setting(False, "keep the raw contact dumps of a run")
    seed: int = setting(20141, "insertion seed of the first replicate", ge=1, le=1000000000)

    def phase_time(self, phase: str, rpm: float) -> float:
        """Length (s) of the spin-up or sampling phase at `rpm`: `<phase>_revolutions` impeller
        revolutions, but at least `<phase>_time` seconds."""
        revolutions = getattr(self, f"{phase}_revolutions")
        return max(getattr(self, f"{phase}_time"), revolutions * 60.0 / float(rpm))


class DemLimits(Settings):
    """Bounds on what one DEM run may cost (`dem.limits`): a plan above any is refused before
    anything runs (`pbmdem.dem.plan.check_limits`; docs/dem.md, "A run")."""

    max_steps: int = setting(
        5000000, "time steps of settling + spin-up + sampling (~40x the default grid's longest run, 1.2e5)", ge=1
    )
    max_simulated_time: float = setting(
        30.0, "simulated time of one run (the default grid's longest: 0.95 s)", "s", gt=0
    )
    max_particle_steps: float = setting(
        1.0e10, "particles x steps of one run, its cost: ~4e6 particle-steps/s on one core, so 1e10 is ~40 min", gt=0
    )


class DemExecution(Settings):
    """How DEM runs are executed (`dem.mpi_ranks`, `dem.timeout` in s, the cost bounds
    `dem.limits`): never part of a result, so never part of a rule's params (changing them
    reruns nothing)."""

    mpi_ranks: int = setting(1, "MPI ranks of one LIGGGHTS run", ge=1, le=4096)
    timeout: float = setting(7200.0, "wall-time limit per run", "s", gt=0)
    limits: DemLimits = setting(DemLimits, "bounds on the plan of one DEM run")

    @classmethod
    def of_job(cls, config: dict, resources=None) -> DemExecution:
        """The execution settings of a Snakemake job: those of the workflow's completed config,
        the ranks replaced by the job's `tasks` resource when a cluster profile sets it."""
        tasks = resources.get("tasks") if resources is not None else None
        own = {key: config["dem"][key] for key in cls.model_fields}
        return cls(**own | ({"mpi_ranks": int(tasks)} if tasks else {}))


class DemSection(Dem, DemExecution):
    """The `dem:` section: what a run computes, its execution, the bed and the replicates."""

    bed_height: float = setting(..., "settled bed height", "m", gt=0, le=10)
    packing_fraction: float = setting(..., "packing fraction of the settled bed", ge=0.3, le=0.74)
    replicates: int = setting(3, "DEM runs per operating point, differing only by their insertion seeds", ge=1, le=1000)


#: keys of the `dem:` section that change how a run is executed, not its result
EXECUTION_KEYS = tuple(DemExecution.model_fields)
