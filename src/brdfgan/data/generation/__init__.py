"""Writing a dataset: the shard jobs of a spec, each material's crops photographed with Mitsuba
into shards, manifests and their SHA-256 records, resuming and repairing (``generation``), and the
typed top level of ``generate.py``'s config (``generate_config``). The top of ``data/``: it reads
the spec, the materials and the phone below it, and nothing below imports it."""
