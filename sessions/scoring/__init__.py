"""Scoring and judging: sessions scored in process or on Dask workers (`workers`), the study
analysis as declared (`analysis`), a session against the experts (`review`), pass marks as records
(`standards`) and the verdicts they give (`verdicts`), ratings, and the study's groups."""
