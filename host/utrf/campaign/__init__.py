"""Campaigns: many runs of a model or of the twin, described in a TOML file, run on Dask
(``utrf campaign run FILE``), results as Parquet (``utrf campaign report DIR``):
docs/campaigns.md."""
