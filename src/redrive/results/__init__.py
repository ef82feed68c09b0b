"""The results store (L2): one run directory per run — manifest.json plus per-frame outputs as
Parquet — read and written here so engine, evaluation and GUI share it without importing each
other."""
