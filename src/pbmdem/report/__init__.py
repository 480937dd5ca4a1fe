"""The report of the study for Snakemake's report (rules/report.smk), from the workflow's result
files: nothing here recomputes a result (docs/validation.md, "Report"). Its modules, one concept
each: docs/architecture.md ("Packages and modules").
"""
