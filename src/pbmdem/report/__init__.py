"""The report of the study: figures, display tables, statements and provenance, from the workflow's
result files, for Snakemake's own report (`snakemake --report report.zip`) and for the
self-contained page `results/report/report.html`.

| module | concept |
| --- | --- |
| `display` | units and number formats of the report (sizes in mm, fractions in %), tables split to fit a page |
| `frequencies` | the collision frequencies of every coupling interval, and the surrogate on PBM-DEM's samples |
| `figures` | the figures of one validation speed (size bands, PSD evolution, liquid and porosity, frequencies) |
| `tables` | the process settings, the speeds, and the comparison table in display form |
| `statements` | the targets (met or not, with the measured values) and the out-of-domain statement |
| `provenance` | configuration hash, git commit, versions of LIGGGHTS, Python and the libraries |
| `html` | HTML pages of the tables, and the self-contained `results/report/report.html` from the same files |
| `outputs` | the files of the report rules (rules/report.smk), one function per rule |

Nothing here recomputes a result: the report reads the files the workflow wrote (docs/validation.md).
"""
