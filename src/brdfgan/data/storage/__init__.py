"""Datasets on disk: generation from a spec (``generation``, its Hydra config ``generate_config``),
the shard format (``shards``) and the spec's range checks (``spec_checks``)."""
