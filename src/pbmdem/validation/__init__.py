"""The validation study: PBM-ANN and PBM-constant against the replicated PBM-DEM reference.

| module | concept |
| --- | --- |
| `results` | reading one speed's results (replicates, ensemble members) |
| `bands` | the PBM-DEM replicate band and a model's distance outside it |
| `comparison` | the comparison table (`results/report/comparison.csv`) |
| `proposals` | the next operating points where the surrogate is least sure or out of its domain |
| `pair_samples` | the surrogate's pair frequency on the PBM-DEM loops' own samples (`pair_samples.csv`) |
| `feed_check` | the feed study's most surprising case (a stated rule) and its PBM-DEM check |
"""
