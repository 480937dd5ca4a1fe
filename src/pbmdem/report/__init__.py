"""The report of the study: figures, display tables, statements and provenance, from the workflow's
result files, for Snakemake's report (`snakemake --report report.html`, the one report: every
figure and table registered with `report()` in rules/report.smk, captions in workflow/report/).

Its modules, one concept each: docs/architecture.md ("Packages and modules").

Nothing here recomputes a result: the report reads the files the workflow wrote (docs/validation.md).
"""
