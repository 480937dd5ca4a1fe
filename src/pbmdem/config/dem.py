"""Settings of the DEM stage: what one LIGGGHTS run computes, how many replicates, how it runs."""

from __future__ import annotations

from dataclasses import dataclass

from .typed import Settings


@dataclass(frozen=True)
class Dem(Settings):
    """What one DEM run computes (the `dem:` section without the bed, which belongs to the
    granulator, without `replicates`, which decides which runs exist, and without the execution
    settings, which change how a run is executed but not its result)."""

    max_particles: int
    timestep_fraction: float
    settle_time: float
    spinup_time: float
    spinup_revolutions: float
    sampling_time: float
    sampling_revolutions: float
    history_time: float
    encounter_gap_fraction: float
    position_every: int
    collision_interval: int | str
    vtk_interval: float
    keep_contact_dumps: bool
    seed: int

    def phase_time(self, phase: str, rpm: float) -> float:
        """Length (s) of the spin-up or sampling phase at `rpm`: `<phase>_revolutions` impeller
        revolutions, but at least `<phase>_time` seconds."""
        revolutions = getattr(self, f"{phase}_revolutions")
        return max(getattr(self, f"{phase}_time"), revolutions * 60.0 / float(rpm))


@dataclass(frozen=True)
class DemLimits(Settings):
    """Bounds on what one DEM run may cost (`dem.limits`): a plan above any of them is refused
    before anything runs (`pbmdem.dem.plan.check_limits`). Guards, not settings of a result."""

    max_steps: int
    max_simulated_time: float
    max_particle_steps: float


@dataclass(frozen=True)
class DemExecution(Settings):
    """How DEM runs are executed (`dem.mpi_ranks`, `dem.timeout` in s, the cost bounds
    `dem.limits`): never part of a result, so never part of a rule's params (changing them
    reruns nothing)."""

    mpi_ranks: int
    timeout: float
    limits: DemLimits

    @classmethod
    def of_job(cls, config: dict, resources=None) -> DemExecution:
        """The execution settings of a Snakemake job: `dem.mpi_ranks` and `dem.timeout` of the
        workflow's completed config, the ranks replaced by the job's `tasks` resource when a
        cluster profile sets it."""
        dem = config["dem"]
        ranks = int(dem["mpi_ranks"])
        tasks = resources.get("tasks") if resources is not None else None
        if tasks:
            ranks = int(tasks)
        limits = DemLimits.from_dict(dem["limits"], "dem.limits")
        return cls(mpi_ranks=ranks, timeout=float(dem["timeout"]), limits=limits)


#: keys of the `dem:` section that are not in `Dem`
BED_KEYS = ("bed_height", "packing_fraction")
EXECUTION_KEYS = ("mpi_ranks", "timeout", "limits")
REPLICATES_KEY = "replicates"
