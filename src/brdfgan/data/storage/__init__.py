"""Datasets on disk, the bottom of ``data/``: the shard format (``shards``: members, encodings,
manifests, SHA-256 records) and the range checks every spec class uses (``spec_checks``). It
imports nothing else of ``data/``; writing a dataset is ``data/generation``."""
