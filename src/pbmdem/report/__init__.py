"""The report of the study: figures, display tables, statements and provenance, from the workflow's
result files, for Snakemake's report (`snakemake --report report.html`, the one report: every
figure and table registered with `report()` in rules/report.smk, captions in workflow/report/).

| module | concept |
| --- | --- |
| `display` | units and number formats (sizes in mm, fractions in %), page-fitting tables, a table as CSV + HTML |
| `frequencies` | the collision frequencies of every coupling interval, and the surrogate on PBM-DEM's samples |
| `figures` | the figures of one validation speed (size bands, PSD evolution, liquid and porosity, frequencies) |
| `tables` | the process settings, the speeds, and the comparison table in display form |
| `statements` | the targets (met or not, with the measured values) and the out-of-domain statement |
| `training` | the surrogate's training set (DEM runs, points, replicates, speeds, feeds), held-out accuracy |
| `provenance` | configuration hash, git commit, versions of LIGGGHTS, Python and libraries, the kernel source |
| `outputs` | the files of the table rules (figures: `figures.write_speed`, `findings.write_findings`) |

Nothing here recomputes a result: the report reads the files the workflow wrote (docs/validation.md).
"""
